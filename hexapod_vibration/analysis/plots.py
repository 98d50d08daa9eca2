"""Figures of an analysed bag (matplotlib, Agg backend: no display needed), 150 dpi.

- ``spectra.png`` (paper Figs. 5-8): z-axis PSD without and with control in separate panels
  on the same scales, and a zoom around the notch tones with both curves; the spectra
  also as ``spectra.csv`` for other tools.
- ``plant_response.png`` (paper Fig. 4, when the report has a harmonic-distortion analysis:
  ``report_harmonics_of_hz``, the ``plant_response`` scenario): z-axis acceleration over a
  few periods of the fundamental and its spectrum with each harmonic's level relative to
  the fundamental. Elsewhere a "fundamental" fitted to a mix of tones means nothing.
- ``convergence.png``: each tone's level over time (the one definition,
  :func:`hexapod_vibration.core.spectrum.tone_level_over_time`) with control-on, the
  identification and each convergence time marked; the notch weights per tone
  (mean over the six struts, and their range).
- ``pointing.png``: tilts, twist and translations of the top plate from the eddy-current
  sensors: the pose's 0.1 s means (the pointing, y axes fitted to the run outside the
  start-up and the identification, which are shaded) beside the vibration RMS within each
  0.1 s (log scale), each group on its own axis.
- ``frequencies.png`` (when a recorded frequency moves: a drifting or sweeping tone, a
  tracking notch, a tachometer): the controller's estimate of each tone
  (``/pph/notch_frequencies``) against the true frequency of every sounding tone
  (``/pph/disturbance_frequencies``) and the tachometer (``/pph/reference_frequency``) over
  time, and the estimation error of each controlled tone.
- ``sensitivity.png`` (when ``/pph/notch_sensitivity`` was recorded, or with a twin): the
  predicted |S|, the measured ratio of the controlled to the uncontrolled z spectrum and,
  with a twin (``analyze --twin``), the H1 estimate from the twin's z to the controlled z, in
  dB, over 0..fs/2 and around the notch tones; the dB axis spans what was measured down to
  :data:`SENSITIVITY_DEPTH_DB` (:func:`sensitivity_limits_db`), the +1 dB of "never worse
  than off" marked.
"""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from hexapod_vibration.analysis.bag_signals import FS, POSE_BLOCK, BagSignals  # noqa: E402
from hexapod_vibration.analysis.report import Analysis  # noqa: E402
from hexapod_vibration.contract import (  # noqa: E402
    DISTURBANCE_FREQUENCIES_TOPIC,
    NEVER_WORSE_DB,
    NOTCH_FREQUENCIES_TOPIC,
    REFERENCE_FREQUENCY_TOPIC,
)
from hexapod_vibration.core import spectrum  # noqa: E402

G0 = spectrum.G0
DPI = 150
COLORS = {"uncontrolled": "tab:blue", "controlled": "tab:red"}
LABELS = {"uncontrolled": "without control", "controlled": "with control"}
plt.rcParams.update({"font.size": 9, "axes.titlesize": 10, "axes.labelsize": 9,
                     "legend.fontsize": 8, "figure.dpi": DPI})


MOVING_HZ = 0.01
"""A recorded frequency whose range exceeds this (Hz) moves: frequencies.png is drawn."""


def write_all(out: Path, signals: BagSignals, result: Analysis) -> list[Path]:
    """Write every figure (and CSV) that means something for this bag; return their paths."""
    paths = [spectra_figure(out / "spectra.png", result),
             spectra_csv(out / "spectra.csv", result)]
    if result.harmonics:
        paths.append(plant_response_figure(out / "plant_response.png", result))
    if result.levels_over_time:
        paths.append(convergence_figure(out / "convergence.png", signals, result))
    eddy = signals.series.get("/pph/eddy")
    if eddy is not None and eddy.sample_index.size > 1:
        paths.append(pointing_figure(out / "pointing.png", signals, result))
    if frequencies_move(signals.frequencies):
        paths.append(frequencies_figure(out / "frequencies.png", signals, result))
    if result.sensitivity_curves:
        paths.append(sensitivity_figure(out / "sensitivity.png", result))
    return paths


def frequencies_move(tracks: dict[str, tuple[np.ndarray, np.ndarray]]) -> bool:
    """Whether any recorded frequency (a tone's estimate or truth, the tachometer) moves.

    ``tracks``: topic -> (sample indices (N,), frequencies (N, K) Hz); a column whose
    range exceeds :data:`MOVING_HZ` moves (two fixed tones side by side do not).
    """
    for _, values in tracks.values():
        columns = np.asarray(values, dtype=float).reshape(len(values), -1)
        for column in columns.T:
            finite = column[np.isfinite(column)]
            if finite.size and float(finite.max() - finite.min()) > MOVING_HZ:
                return True
    return False


# ---------------------------------------------------------------------------- spectra
def _psd_db(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Welch PSD of the z acceleration in dB re 1 g^2/Hz (the tables' spectrum)."""
    f, psd = spectrum.power_spectral_density(x - x.mean(), FS, segment_s=min(
        spectrum.DEFAULT_SEGMENT_S, x.size / FS))
    return f, 10.0 * np.log10(np.maximum(psd, 1e-30) / G0**2)


def _window_psds(result: Analysis) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    out = {}
    for name in ("uncontrolled", "controlled"):
        rows = result.windows.get(name)
        if rows is not None and rows.stop - rows.start >= 16:
            out[name] = _psd_db(result.z[rows])
    return out


def _window_label(result: Analysis, name: str) -> str:
    rows = result.windows[name]
    a = result.index[rows.start] / FS
    return f"{LABELS[name]} ({a:.1f}-{a + (rows.stop - rows.start) / FS:.1f} s)"


def _mark_tones(ax: plt.Axes, result: Analysis, label: bool = True) -> None:
    """Dotted lines at the reported tones (green: notch tones), labelled if they fit."""
    top = ax.get_ylim()[1]
    freqs = sorted(r["frequency_hz"] for r in result.report["tones"])
    lo, hi = ax.get_xlim()
    if len(freqs) > 1 and min(np.diff(freqs)) < (hi - lo) / 40:
        label = False
    for row in result.report["tones"]:
        f = row["frequency_hz"]
        ax.axvline(f, color="tab:green" if row["controlled"] else "0.6", lw=0.7, ls=":",
                   zorder=0)
        if label:
            ax.annotate(f"{f:g}{'*' if row['controlled'] else ''}", (f, top), xytext=(2, -9),
                        textcoords="offset points", fontsize=7, color="0.3")


def spectra_figure(path: Path, result: Analysis) -> Path:
    """Without/with control PSD panels on the same scales, and a zoom on the notch tones."""
    psds = _window_psds(result)
    tones = [r["frequency_hz"] for r in result.report["tones"]]
    notch = [r["frequency_hz"] for r in result.report["tones"] if r["controlled"]]
    top_f = (FS / 2 if result.harmonics is not None
             else min(FS / 2, max(150.0, 1.6 * max(tones, default=100.0))))
    zoom = len(psds) == 2 and bool(notch)
    rows = len(psds) + (1 if zoom else 0)
    fig = plt.figure(figsize=(8.0, 2.6 * rows + 0.3))
    grid = fig.add_gridspec(rows, 1, height_ratios=[1.0] * len(psds) + ([1.1] if zoom else []))
    lo = min(float(np.percentile(db[(f > 2) & (f < top_f)], 1)) for f, db in psds.values())
    hi = max(float(db[(f > 2) & (f < top_f)].max()) for f, db in psds.values())
    ylim = (lo - 5.0, hi + 8.0)
    axes = []
    for k, (name, (f, db)) in enumerate(psds.items()):
        ax = fig.add_subplot(grid[k], sharex=axes[0] if axes else None)
        ax.plot(f, db, color=COLORS[name], lw=0.7)
        ax.set(xlim=(0, top_f), ylim=ylim, ylabel="PSD (dB re 1 g$^2$/Hz)",
               title=f"{result.report['scenario']}: top plate z acceleration, "
                     f"{_window_label(result, name)}")
        ax.grid(alpha=0.3)
        _mark_tones(ax, result)
        axes.append(ax)
    axes[-1].set_xlabel("frequency (Hz)")
    if zoom:
        clusters = _tone_clusters(notch)
        cells = grid[2].subgridspec(1, len(clusters), wspace=0.25)
        for k, cluster in enumerate(clusters):
            _zoom_panel(fig.add_subplot(cells[k]), psds, result, cluster, legend=k == 0)
    return _save(fig, path)


def _tone_clusters(tones: list[float], gap_hz: float = 5.0) -> list[list[float]]:
    """Notch tones grouped when less than ``gap_hz`` apart (one zoom panel each, <= 3)."""
    clusters: list[list[float]] = []
    for f in sorted(tones):
        if clusters and f - clusters[-1][-1] < gap_hz:
            clusters[-1].append(f)
        else:
            clusters.append([f])
    return clusters[:3]


def _zoom_panel(ax: plt.Axes, psds: dict, result: Analysis, notch: list[float],
                legend: bool) -> None:
    """Both spectra around a group of notch tones (and the reported tones beside them)."""
    reported = [r["frequency_hz"] for r in result.report["tones"]]
    near = [f for f in reported if min(abs(f - n) for n in notch) <= 3.0] + notch
    a, b = min(near) - 1.5, max(near) + 1.5
    if b - a < 6.0:
        a, b = 0.5 * (a + b) - 3.0, 0.5 * (a + b) + 3.0
    for name, (f, db) in psds.items():
        sel = (f >= a) & (f <= b)
        ax.plot(f[sel], db[sel], color=COLORS[name], lw=1.2 if name == "uncontrolled" else 1.0,
                ls="-" if name == "uncontrolled" else "--", label=LABELS[name])
    ax.set(xlim=(a, b), xlabel="frequency (Hz)", ylabel="PSD (dB re 1 g$^2$/Hz)",
           title=f"zoom: {', '.join(f'{f:g}' for f in notch)} Hz (notch)")
    _mark_tones(ax, result)
    ax.grid(alpha=0.3)
    if legend:
        ax.legend(loc="best")


def spectra_csv(path: Path, result: Analysis) -> Path:
    """The spectra of the figure as CSV: frequency (Hz), PSD per window (dB re 1 g^2/Hz)."""
    psds = _window_psds(result)
    names = list(psds)
    freq = psds[names[0]][0]
    tmp = path.with_name(f".{path.name}.tmp")
    with tmp.open("w", newline="", encoding="utf-8") as stream:
        writer = csv.writer(stream)
        writer.writerow(["frequency_hz", *[f"{n}_psd_db_re_1g2_per_hz" for n in names]])
        columns = [np.interp(freq, *psds[n]) for n in names]
        for k, f in enumerate(freq):
            writer.writerow([f"{f:.4f}", *[f"{c[k]:.3f}" for c in columns]])
    tmp.replace(path)
    return path


# ---------------------------------------------------------------------------- Fig. 4
def plant_response_figure(path: Path, result: Analysis) -> Path:
    """Time trace (5 periods) and spectrum of the uncontrolled z-axis acceleration.

    For a report with a harmonic-distortion analysis (``result.harmonics``): the
    fundamental and its harmonics' levels relative to it.
    """
    rows = result.windows["uncontrolled"]
    x = result.z[rows]
    hd = result.harmonics
    f0 = hd["frequencies_hz"][0]
    fig, (ax_t, ax_f) = plt.subplots(2, 1, figsize=(8.0, 6.5))
    n = int(round(5 * FS / f0))
    seg = (x[-n:] - x.mean()) / G0 * 1e3
    t_ms = np.arange(seg.size) / FS * 1e3
    ax_t.plot(t_ms, seg, color="tab:blue", lw=1.0, marker=".", ms=2.5)
    sine = _fundamental_fit(seg, f0)
    ax_t.plot(t_ms, sine, color="0.5", lw=0.8, ls="--", label=f"{f0:g} Hz sinusoid fitted")
    ax_t.set(xlabel="time (ms)", ylabel="z acceleration (mg, mean removed)",
             title=f"{result.report['scenario']}: response over 5 periods of {f0:g} Hz "
                   "(samples at 1 kHz)")
    ax_t.legend(loc="upper right")
    f, db = _psd_db(x)
    ax_f.plot(f, db, color="tab:blue", lw=0.7)
    for fk, rel in zip(hd["frequencies_hz"][1:], hd["relative_db"][1:], strict=True):
        ax_f.annotate(f"{rel:.0f}", (fk, float(np.interp(fk, f, db))), xytext=(0, 4),
                      textcoords="offset points", ha="center", fontsize=7)
    ax_f.set_title(f"spectrum: harmonics in dB re the fundamental; THD "
                   f"{hd['thd_percent']:.1f} % over {hd['harmonics']} harmonics "
                   "below fs/2")
    ax_f.set(xlabel="frequency (Hz)", ylabel="PSD (dB re 1 g$^2$/Hz)", xlim=(0, FS / 2))
    for ax in (ax_t, ax_f):
        ax.grid(alpha=0.3)
    return _save(fig, path)


def _fundamental_fit(x: np.ndarray, f0: float) -> np.ndarray:
    """Least-squares sinusoid at f0 through x (same units)."""
    t = np.arange(x.size) / FS
    basis = np.column_stack([np.cos(2 * np.pi * f0 * t), np.sin(2 * np.pi * f0 * t),
                             np.ones_like(t)])
    coef, *_ = np.linalg.lstsq(basis, x, rcond=None)
    return basis @ coef


# ---------------------------------------------------------------------------- convergence
LEGEND_INSIDE_MAX = 6
"""More entries than this go beside the levels' axis instead of over the curves."""


def convergence_figure(path: Path, signals: BagSignals, result: Analysis) -> Path:
    """Tone levels over time with control-on, identification and convergence marked."""
    on = signals.control_on_sample / FS
    wide = len(result.levels_over_time) + 2 > LEGEND_INSIDE_MAX
    fig, (ax_e, ax_w) = plt.subplots(2, 1, figsize=(9.5 if wide else 8.0, 6.8), sharex=True,
                                     height_ratios=[1.4, 1])
    rows = {r["frequency_hz"]: r for r in result.report["tones"]}
    for k, (f, lev) in enumerate(result.levels_over_time.items()):
        controlled = rows[f]["controlled"]
        color = f"C{k}"
        conv = lev["convergence_s"]
        label = f"{f:g} Hz{' (notch)' if controlled else ''}"
        if controlled and np.isfinite(conv):
            label += f": converged in {conv:.2f} s"
        ax_e.plot(lev["t_s"], lev["level_db"], color=color, lw=1.4 if controlled else 0.8,
                  ls="-" if controlled else ":", alpha=1.0 if controlled else 0.7, label=label)
        if controlled and np.isfinite(conv):
            t_c = on + conv
            ax_e.plot(t_c, np.interp(t_c, lev["t_s"], lev["level_db"]), "v", color=color,
                      ms=7, mec="k", mew=0.5)
            ax_e.axvline(t_c, color=color, lw=0.7, ls="--")
    t_first = min(v["t_s"][0] for v in result.levels_over_time.values() if v["t_s"].size)
    _shade_identification(ax_e, result, max(t_first - 1.0, 0.0))
    ax_e.axvline(on, color="k", lw=1.0, label=f"control on ({on:.2f} s)")
    windows = {round(v["level_window_s"], 3) for v in result.details["convergence"].values()}
    moving = frequencies_move(signals.frequencies)
    ax_e.set(ylabel="tone level (dB re 1 g)",
             title="tone levels over time (Blackman-Harris window "
                   f"{', '.join(f'{w:g}' for w in sorted(windows))} s); "
                   "\u25bc: within 3 dB of the final level"
                   + ("\nat fixed frequencies: a tone that moves leaves them "
                      "(frequencies.png)" if moving else ""))
    ax_e.set_xlim(max(t_first - 1.0, 0.0), result.index[-1] / FS)
    entries = len(ax_e.get_legend_handles_labels()[0])
    if entries > LEGEND_INSIDE_MAX:
        ax_e.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7)
    else:
        ax_e.legend(loc="upper right", ncol=2)
    _weights_panel(ax_w, signals, result, on)
    for ax in (ax_e, ax_w):
        ax.grid(alpha=0.3)
    return _save(fig, path)


def _shade_identification(ax: plt.Axes, result: Analysis, t_from: float) -> None:
    """Grey spans where the notch identified the plant (those after ``t_from`` s)."""
    t1 = result.index[-1] / FS
    labelled = False
    for a, b in result.identification:
        a_s, b_s = max(a / FS, t_from), min(b / FS, t1)
        if a_s < b_s:
            ax.axvspan(a_s, b_s, color="0.85", zorder=0,
                       label=None if labelled else "identification")
            labelled = True


def _weights_panel(ax: plt.Axes, signals: BagSignals, result: Analysis, on: float) -> None:
    """Mean |W| over the six struts per tone, with the struts' range shaded."""
    t_start = result.levels_over_time and min(v["t_s"][0] for v in
                                              result.levels_over_time.values()
                                              if v["t_s"].size)
    keep = signals.weights_index / FS >= (t_start or 0.0)
    if signals.weights.size and keep.any():
        t_w = signals.weights_index[keep] / FS
        magnitude = np.hypot(signals.weights[keep, ..., 0], signals.weights[keep, ..., 1])
        tones = signals.notch_tones() or list(range(magnitude.shape[1]))
        for k in range(magnitude.shape[1]):
            color = _tone_color(result, tones[k], f"C{k}")
            ax.fill_between(t_w, magnitude[:, k].min(axis=1), magnitude[:, k].max(axis=1),
                            color=color, alpha=0.25, lw=0)
            ax.plot(t_w, magnitude[:, k].mean(axis=1), color=color, lw=1.2,
                    label=f"{tones[k]:.5g} Hz: mean of 6 struts (band: min-max)")
        peaks = magnitude.max(axis=(0, 2))
        if peaks.size > 1 and peaks.min() > 0 and peaks.max() / peaks.min() > 10:
            ax.set_yscale("log")          # tones whose weights differ by decades
            ax.set_ylim(bottom=max(1e-3, 0.3 * float(peaks.min()) / 10))
        ax.legend(loc="lower right")
    else:
        ax.text(0.5, 0.5, "no /pph/notch_weights in the bag over this time",
                transform=ax.transAxes, ha="center", va="center")
    ax.axvline(on, color="k", lw=1.0)
    ax.set(xlabel="sim time (s)", ylabel="notch weight |W| (N)",
           title="notch weights (amplitude of each strut's cancelling force)")


def _tone_color(result: Analysis, f: float, other: str) -> str:
    """The colour of tone ``f`` in the levels panel, else ``other`` (a tone that moved)."""
    for k, tone in enumerate(result.levels_over_time):
        if abs(tone - f) < 1e-6:
            return f"C{k}"
    return other


# ---------------------------------------------------------------------------- pointing
POSE_GROUPS = (
    ("tilt (urad)", ((3, "tilt x"), (4, "tilt y")), 1e6),
    ("twist (urad)", ((5, "twist"),), 1e6),
    ("translation (um)", ((0, "x"), (1, "y"), (2, "z")), 1e6),
)
STARTUP_S = 2.0


def pointing_figure(path: Path, signals: BagSignals, result: Analysis) -> Path:
    """Pose of the top plate from the eddy sensors: tilts, twist, translations.

    Left, the pose's mean over each 0.1 s (the pointing), its axis fitted to the run
    outside the start-up and the identification (shaded; what they excite may leave the
    axis); right, the RMS deviation within each 0.1 s (the vibration), log scale.
    """
    eddy = signals.series["/pph/eddy"]
    mean, rms = eddy.values[:, :6], eddy.values[:, 6:]
    t = (eddy.sample_index + 0.5 * POSE_BLOCK) / FS
    quiet = quiet_samples(t, [(a / FS, b / FS) for a, b in result.identification])
    fig, axes = plt.subplots(len(POSE_GROUPS), 2, figsize=(11.0, 7.0), sharex=True,
                             squeeze=False)
    on = signals.control_on_sample
    for row, (ylabel, members, scale) in zip(axes, POSE_GROUPS, strict=True):
        ax_mean, ax_rms = row
        for k, name in members:
            y = mean[:, k] * scale
            line, = ax_mean.plot(t, y, lw=1.0, label=name)
            ax_rms.plot(t, np.maximum(rms[:, k] * scale, 1e-30), lw=1.0,
                        color=line.get_color(), label=name)
        ax_mean.set(ylabel=f"{ylabel}, 0.1 s mean",
                    ylim=pose_limits(mean[:, [k for k, _ in members]] * scale, quiet))
        ax_rms.set(ylabel=f"{ylabel}, RMS in 0.1 s", yscale="log")
        for ax in row:
            _shade_identification(ax, result, 0.0)
            if on is not None:
                ax.axvline(on / FS, color="k", lw=0.8, ls="--")
            ax.legend(loc="upper right", ncol=len(members))
            ax.grid(alpha=0.3)
    axes[0][0].set_title("pointing: pose, 0.1 s means (axes fit the quiet run)")
    axes[0][1].set_title("vibration: RMS deviation within each 0.1 s")
    for ax in axes[-1]:
        ax.set_xlabel("sim time (s)" + ("; dashed: control on" if on is not None else ""))
    return _save(fig, path)


def quiet_samples(t_s: np.ndarray, excited_s: list[tuple[float, float]]) -> np.ndarray:
    """Rows of ``t_s`` after the start-up and outside the ``excited_s`` spans (bool)."""
    quiet = t_s >= min(STARTUP_S, float(t_s[-1]) / 2)
    for a, b in excited_s:
        quiet &= ~((t_s >= a) & (t_s < b))
    return quiet if np.any(quiet) else np.ones_like(quiet)


def pose_limits(values: np.ndarray, rows: np.ndarray) -> tuple[float, float]:
    """The y limits of pose means: their 0.5-99.5 % range over ``rows``, padded by 15 %."""
    lo, hi = np.percentile(values[rows], [0.5, 99.5])
    pad = max(0.15 * float(hi - lo), 1e-3)
    return float(lo) - pad, float(hi) + pad


# ---------------------------------------------------------------------------- frequencies
def frequencies_figure(path: Path, signals: BagSignals, result: Analysis) -> Path:
    """Estimated against true frequencies over time, and each controlled tone's error."""
    tracks = signals.frequencies
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8.0, 6.0), sharex=True,
                                      gridspec_kw={"height_ratios": [2, 1]})
    truth = tracks.get(DISTURBANCE_FREQUENCIES_TOPIC)
    if truth is not None:
        for j in range(truth[1].shape[1]):
            top.plot(truth[0] / FS, truth[1][:, j], color="0.6", lw=2.5,
                     label="true (driver)" if j == 0 else None)
    reference = tracks.get(REFERENCE_FREQUENCY_TOPIC)
    if reference is not None:
        top.plot(reference[0] / FS, reference[1][:, 0], color="k", lw=0.8, ls=":",
                 label="tachometer")
    estimate = tracks.get(NOTCH_FREQUENCIES_TOPIC)
    if estimate is not None:
        for k in range(estimate[1].shape[1]):
            top.plot(estimate[0] / FS, estimate[1][:, k], color=f"C{k}", lw=1.0,
                     label=f"notch tone {k + 1} (estimate)")
    _errors_panel(bottom, signals, result)
    on = signals.control_on_sample
    for ax in (top, bottom):
        if on is not None:
            ax.axvline(on / FS, color="k", lw=0.8, ls="--")
        ax.grid(alpha=0.3)
    top.set(ylabel="frequency (Hz)", title="tone frequencies: the controller's estimates "
            "and the true ones (dashed: control on)")
    top.legend(loc="best")
    return _save(fig, path)


def _errors_panel(ax: plt.Axes, signals: BagSignals, result: Analysis) -> None:
    """Estimate minus true frequency (Hz) of each controlled tone the report follows."""
    from hexapod_vibration.analysis import moving_tones

    truth = signals.frequencies.get(DISTURBANCE_FREQUENCIES_TOPIC)
    estimate = signals.frequencies.get(NOTCH_FREQUENCIES_TOPIC)
    shown = False
    if truth is not None and estimate is not None:
        targets = [float(np.nanmedian(estimate[1][:, k])) for k in range(estimate[1].shape[1])]
        for k, j in enumerate(moving_tones.match_columns(truth[1], targets)):
            if j is None:
                continue
            true_hz = moving_tones.track_on_samples(truth[0], truth[1][:, j], estimate[0])
            ax.plot(estimate[0] / FS, estimate[1][:, k] - true_hz, color=f"C{k}", lw=1.0,
                    label=f"notch tone {k + 1}")
            shown = True
    if shown:
        ax.legend(loc="best")
    else:
        ax.text(0.5, 0.5, "needs /pph/notch_frequencies and /pph/disturbance_frequencies",
                transform=ax.transAxes, ha="center", va="center")
    ax.set(xlabel="sim time (s)", ylabel="estimate - true (Hz)")


# ---------------------------------------------------------------------------- sensitivity
SENSITIVITY_DEPTH_DB = 40.0
"""The sensitivity axis goes at most this far below 0 dB: deeper notches leave the axis
(their depth is the report's tone table); the +-5 dB that matter stay readable."""
SENSITIVITY_TOP_DB = 20.0
"""... and at most this far above it (a measured ratio that high is a broken loop)."""


def sensitivity_limits_db(curves_db: list[np.ndarray]) -> tuple[float, float]:
    """The dB axis of the sensitivity figure: what was measured, clipped to a useful range.

    From the lowest value with signal (the measured ratios floor where the controlled
    spectrum meets the noise; the predicted |S| is exactly zero at a tone) rounded down to
    5 dB, no deeper than :data:`SENSITIVITY_DEPTH_DB`, to the highest (99.9 %) rounded up,
    at least +5 dB (the never-worse line shows) and at most :data:`SENSITIVITY_TOP_DB`.
    """
    values = np.concatenate([np.asarray(c, dtype=float).ravel() for c in curves_db] or [[]])
    values = values[np.isfinite(values)]
    if not values.size:
        return -SENSITIVITY_DEPTH_DB, 5.0
    lo = max(5.0 * np.floor(float(values.min()) / 5.0), -SENSITIVITY_DEPTH_DB)
    hi = 5.0 * np.ceil(float(np.percentile(values, 99.9)) / 5.0)
    return float(min(lo, -5.0)), float(min(max(hi, 5.0), SENSITIVITY_TOP_DB))


def sensitivity_figure(path: Path, result: Analysis) -> Path:
    """Predicted |S| against the measured controlled/uncontrolled spectrum ratio (dB).

    With a twin comparison, also the H1 estimate from the twin's z to the controlled z.
    Over 0..fs/2 and around the notch tones, on the axis of :func:`sensitivity_limits_db`.
    """
    curves = result.sensitivity_curves
    view = result.report.get("sensitivity", {}).get("view", "")
    notch = [r["frequency_hz"] for r in result.report["tones"] if r["controlled"]]
    spans = [(0.0, FS / 2.0)]
    if notch:
        spans.append((max(min(notch) - 8.0, 0.0), max(notch) + 8.0))
    drawn = [("measured_frequency_hz", "measured_db", dict(
                  color="tab:red", lw=0.7, label="measured: controlled / uncontrolled spectrum")),
             ("twin_frequency_hz", "twin_db", dict(
                  color="tab:green", lw=0.8, label="measured: H1 from the twin (no control)")),
             ("frequency_hz", "predicted_db", dict(
                  color="k", lw=1.3, label=f"predicted |S| ({view}) before control"))]
    shown = [(f, d, style) for f, d, style in drawn if f in curves]
    limits = sensitivity_limits_db([curves[d] for f, d, _ in shown if f != "frequency_hz"]
                                   or [curves[d] for _, d, _ in shown])
    fig, axes = plt.subplots(len(spans), 1, figsize=(8.0, 3.2 * len(spans) + 0.4),
                             squeeze=False)
    for ax, (lo, hi) in zip(axes[:, 0], spans, strict=True):
        for f_key, db_key, style in shown:
            sel = (curves[f_key] >= lo) & (curves[f_key] <= hi)
            ax.plot(curves[f_key][sel], curves[db_key][sel], **style)
        for f in notch:
            if lo <= f <= hi:
                ax.axvline(f, color="0.5", lw=0.6, ls=":")
        ax.axhline(0.0, color="0.5", lw=0.6)
        ax.axhline(NEVER_WORSE_DB, color="tab:orange", lw=1.0, ls="--",
                   label=f"+{NEVER_WORSE_DB:g} dB: never worse than off")
        ax.set(xlim=(lo, hi), ylim=limits, xlabel="frequency (Hz)",
               ylabel="|S| (dB, with / without control)")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="lower right", fontsize=7)
    deeper = any(np.nanmin(curves[d]) < limits[0] for _, d, _ in shown)
    not_compared = result.report.get("sensitivity", {}).get("not_compared")
    axes[0, 0].set_title("sensitivity: predicted vs measured (dotted: notch tones"
                         + ("; deeper notches leave the axis)" if deeper else ")")
                         + (f"\nnot comparable at the tones: {not_compared}"
                            if not_compared else ""))
    return _save(fig, path)


def _save(fig: plt.Figure, path: Path) -> Path:
    fig.tight_layout()
    tmp = path.with_name(f".{path.stem}.tmp{path.suffix}")
    fig.savefig(tmp, dpi=DPI)
    plt.close(fig)
    tmp.replace(path)
    return path
