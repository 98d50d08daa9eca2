"""paths: data files are found in the source tree when the package is not in the ament index."""

import pytest

from hexapod_vibration import paths


def test_share_directory_holds_config():
    assert (paths.share_directory() / "config").is_dir()


def test_unknown_scenario_lists_available(tmp_path, monkeypatch):
    (tmp_path / "config" / "scenarios").mkdir(parents=True)
    (tmp_path / "config" / "scenarios" / "close_tones.yaml").write_text("{}")
    (tmp_path / "config" / "scenarios" / "plant_response.yaml").write_text("{}")
    monkeypatch.setattr(paths, "share_directory", lambda: tmp_path)
    assert paths.scenario_path("close_tones") == tmp_path / "config/scenarios/close_tones.yaml"
    with pytest.raises(FileNotFoundError, match="available scenarios: close_tones, plant_response"):
        paths.scenario_path("single_tone")


def test_unknown_config_lists_available(tmp_path, monkeypatch):
    (tmp_path / "config").mkdir()
    (tmp_path / "config" / "pph_model.yaml").write_text("{}")
    monkeypatch.setattr(paths, "share_directory", lambda: tmp_path)
    with pytest.raises(FileNotFoundError, match="available: pph_model.yaml"):
        paths.config_path("missing.yaml")


def test_source_tree_fallback_without_ament_prefix(monkeypatch):
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    assert paths.share_directory() == paths._source_root()
