"""What the experiment runner records about a run, in the bag's ``custom_data``."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field


@dataclass(frozen=True)
class RunRecord:
    """What the experiment runner recorded about a run, in the bag's ``custom_data``.

    Sample numbers are loop samples (1 kHz); -1 means none.
    """

    scenario: str
    report_tones_hz: list[float]
    notch_tones_hz: list[float]
    window_s: float
    samples: int
    control_on_sample: int = -1
    identify_at_sample: int = -1
    identification_samples: int = 0
    harmonics_of_hz: float = 0.0
    paper_reduction_db: dict[str, float] = field(default_factory=dict)
    mode: str = "lockstep"

    def to_json(self) -> str:
        """One-line JSON (the ``custom_data`` value)."""
        return json.dumps(asdict(self), separators=(",", ":"))

    @classmethod
    def from_json(cls, text: str) -> RunRecord:
        """Parse :meth:`to_json`; ValueError if it is not a run record."""
        try:
            data = json.loads(text)
            return cls(**{k: data[k] for k in cls.__dataclass_fields__ if k in data})
        except (TypeError, KeyError, json.JSONDecodeError) as err:
            raise ValueError(f"not a run record: {err}") from None

    def paper(self) -> dict[float, float]:
        """The paper's reductions (dB) by frequency (Hz)."""
        return {float(k): float(v) for k, v in self.paper_reduction_db.items()}
