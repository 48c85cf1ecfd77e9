"""The Figure 7 bench's bookkeeping: curriculum steps, resampling, reuse of runs, the summary over seeds."""
import importlib.util
from pathlib import Path

import numpy as np
import pytest

_PATH = Path(__file__).resolve().parents[1] / "bench" / "bench_figure7.py"
_spec = importlib.util.spec_from_file_location("bench_figure7", _PATH)
fig7 = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fig7)


def _metrics(stages, complete):
    steps = np.arange(1, len(stages) + 1) * 1000.0
    return {"step": steps, "curriculum_stage": np.asarray(stages, float), "curriculum_complete": np.asarray(complete, float)}


def test_curriculum_steps():
    m = _metrics([1, 1, 4, 10, 10, 10], [0, 0, 0, 0, 1, 1])
    assert fig7.curriculum_steps(m) == (10.0, 4000, 5000)
    m = _metrics([1, 2, 3], [0, 0, 0])
    assert fig7.curriculum_steps(m) == (3.0, None, None)
    m = _metrics([10, 10], [0, 0])  # no curriculum: the last stage from the start
    assert fig7.curriculum_steps(m) == (10.0, 0, None)


def test_resample_interpolates_and_stops_at_the_run_end():
    m = {"step": np.array([0.0, 10.0, 20.0]), "success_rate": np.array([0.0, np.nan, 1.0])}
    y = fig7.resample(m, "success_rate", np.array([0.0, 5.0, 20.0, 30.0]))
    np.testing.assert_allclose(y[:3], [0.0, 0.25, 1.0])
    assert np.isnan(y[3])
    assert np.isnan(fig7.resample(m, "missing", np.array([1.0]))).all()


def test_run_status(tmp_path):
    assert fig7.run_status(tmp_path, 100) == "new"
    (tmp_path / "latest.pt").write_bytes(b"x")
    assert fig7.run_status(tmp_path, 100) == "partial"  # no metrics yet
    (tmp_path / "metrics.csv").write_text("step,success_rate\n50,0.1\n")
    assert fig7.run_status(tmp_path, 100) == "partial"
    (tmp_path / "metrics.csv").write_text("step,success_rate\n50,0.1\n100,0.2\n")
    assert fig7.run_status(tmp_path, 100) == "done"


def test_summary_against_hand_computation():
    def row(run, seed, success, passed):
        return {"run": run, "seed": seed, "success": success, "passed_at": passed}

    rows = [row("ours", 0, 0.40, 900), row("ours", 1, 0.50, 1100), row("ours", 2, 0.45, None),
            row("no-hit-reward", 0, 0.30, None), row("no-hit-reward", 1, 0.55, 700), row("no-hit-reward", 2, 0.35, 800),
            row("no-curriculum", 0, 0.10, None)]  # one seed only
    s = {e["run"]: e for e in fig7.summarize(rows, [0, 1, 2], ["ours", "no-hit-reward", "no-curriculum"])}
    assert s["ours"]["passed_all"] == 2 and s["ours"]["median_passed_at"] == 1000
    assert s["ours"]["success_mean"] == pytest.approx(0.45)
    assert s["ours"]["success_std"] == pytest.approx(0.05)  # sample std of 0.40, 0.50, 0.45
    assert "diff_to_first_mean" not in s["ours"]
    hit = s["no-hit-reward"]
    diffs = np.array([0.10, -0.05, 0.10])
    assert hit["diff_to_first_mean"] == pytest.approx(diffs.mean())
    assert hit["diff_to_first_stderr"] == pytest.approx(diffs.std(ddof=1) / np.sqrt(3))
    assert hit["first_better"] == 2 and hit["paired_seeds"] == 3
    cur = s["no-curriculum"]
    assert cur["seeds"] == 1 and cur["paired_seeds"] == 1 and cur["success_std"] == 0.0
    assert cur["diff_to_first_mean"] == pytest.approx(0.30)


def test_train_variants_passes_each_variants_flags(tmp_path, monkeypatch):
    import mmrl.cli

    calls = []
    monkeypatch.setattr(mmrl.cli, "main", lambda argv: calls.append(argv) or 0)
    chosen = [v for v in fig7.VARIANTS if v[0] in ("ours", "no-hit-no-curriculum")]
    fig7.train_variants(chosen, tmp_path / "db.npz", tmp_path, 1000, 3, "mmrl", ["hit_weight=5"], 0)
    assert [a[a.index("--out") + 1] for a in calls] == [str(tmp_path / "seed3" / "ours"),
                                                         str(tmp_path / "seed3" / "no-hit-no-curriculum")]
    ours, both = calls
    assert "--no-hit-reward" not in ours and "--no-curriculum" not in ours
    assert "--no-hit-reward" in both and "--no-curriculum" in both
    for argv in calls:
        assert argv[argv.index("--preset") + 1] == "mmrl" and argv[argv.index("--set") + 1] == "hit_weight=5"
        assert argv[argv.index("--seed") + 1] == "3"
    assert fig7.PAPER_VARIANTS == ["ours", "no-hit-reward", "no-curriculum"]
