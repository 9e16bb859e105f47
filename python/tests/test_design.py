"""`Study.design` (as `rfmlab design`): the study's own design of the bundled data scored and
written, the `sensors` override, and the errors of the `[design]` section and the output."""

from __future__ import annotations

import polars as pl
import pytest

import rfmlab
from conftest import study_copy

# The study's own four points in +y as the only candidates, Model 4 at its initial values, the
# bundled data's rig (noise 0.2 % of the RMS, 200 averages): a few seconds.
DESIGN = """
[design]
sensors = 4
candidates = "points"
directions = ["y"]
models = ["model4"]
draws = 0
force_noise = 0.002
response_noise = 0.002
n_averages = 200
"""


def plan_study(tmp, name: str, design: str = DESIGN, edits: dict[str, str] | None = None):
    """`studies/bayes.toml` (data paths absolute, its own output folder) with `design` appended."""
    path = study_copy(tmp, "bayes.toml", name, edits)
    path.write_text(path.read_text() + design)
    return path


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("design")
    study = rfmlab.load(plan_study(tmp, "py_design"))
    out = tmp / "plan"
    return study, study.design(output=out), out


def test_the_study_design_is_scored_and_written(planned):
    """The study's own design is its four +y points, Model 4's predicted relative sds are
    positive and below 1 % at both levels, and the files are written and readable."""
    study, plan, out = planned
    assert plan.current is not None
    assert sorted(plan.current.sensors) == ["1 +y", "2 +y", "3 +y", "4 +y"], plan.current.sensors
    assert plan.current.drive == 2
    assert set(plan.current.sd_rel) == {"model4"}
    levels = plan.current.sd_rel["model4"]
    assert set(levels) == {"L1", "L2"}
    for level, sds in levels.items():
        assert set(sds) == {"E0", "h", "E1", "eta1"}, sds
        for p, v in sds.items():
            assert 0 < v < 0.01, (level, p, v)
    worst = max(v for sds in levels.values() for v in sds.values())
    assert plan.current.worst_sd_rel == pytest.approx(worst, rel=1e-12)
    assert plan.current.info_gain > 0
    # Four sensors among four candidates: the best design holds the same points.
    assert sorted(plan.best.sensors) == sorted(plan.current.sensors)
    assert plan.best.worst_sd_rel <= plan.current.worst_sd_rel * (1 + 1e-9)

    frame = plan.current.sd_rel_frame()
    assert frame.height == 8 and (frame["sd_rel"] > 0).all()

    for name in ("design.parquet", "design_candidates.parquet", "report.md", "manifest.json"):
        assert (out / name).is_file(), name
    written = pl.read_parquet(out / "design.parquet")
    assert {"sd_rel_e0", "worst_sd_rel"} <= set(written.columns), written.columns
    # The table returned is the one written.
    assert written.columns == plan.table.columns
    assert written.select("design", "level", "sd_rel_e0").equals(plan.table.select("design", "level", "sd_rel_e0"))
    cur = plan.table.filter((pl.col("design") == "current") & (pl.col("level") == "L1"))
    assert cur["sd_rel_e0"][0] == pytest.approx(levels["L1"]["E0"], rel=1e-12)
    assert plan.candidates.height == 4
    assert plan.candidates["in_current"].sum() == 4
    assert plan.report.startswith("# Test design")
    assert (out / "report.md").read_text().startswith("# Test design")
    assert plan.output == out


def test_sensors_override(tmp_path):
    """`sensors=3` overrides `[design] sensors = 4`: the best design has three sensors."""
    study = rfmlab.load(plan_study(tmp_path, "py_design3"))
    plan = study.design(sensors=3)
    assert len(plan.best.sensors) == 3, plan.best.sensors
    assert all(s.endswith(" +y") for s in plan.best.sensors)
    assert (plan.table.filter(pl.col("design") == "best")["n_sensors"] == 3).all()
    # Nothing is written without `output`.
    assert plan.output is None
    with pytest.raises(rfmlab.StudyError) as e:
        study.design(sensors=0)
    assert e.value.key == "design.sensors"


def test_design_errors(tmp_path):
    """A drive that is not a study point names `design.drives`; a level without its force RMS
    (which the design needs and a run does not) names that key; an output folder holding
    other files is refused before anything is computed, unless forced."""
    bad = plan_study(tmp_path, "py_design_bad", DESIGN + "drives = [9]\n")
    with pytest.raises(rfmlab.StudyError) as e:
        rfmlab.load(bad).design()
    assert "design.drives" in str(e.value)
    assert e.value.key == "design.drives"

    no_force = plan_study(tmp_path, "py_design_noforce", edits={"force_rms_n = 3.3\n": ""})
    with pytest.raises(rfmlab.StudyError) as e:
        rfmlab.load(no_force).design()
    assert e.value.key == "measurements.levels[0].force_rms_n", e.value

    taken = tmp_path / "taken"
    taken.mkdir()
    (taken / "mine.txt").write_text("not rfmlab's")
    study = rfmlab.load(plan_study(tmp_path, "py_design_taken"))
    with pytest.raises(rfmlab.RunError) as e:
        study.design(output=taken)
    assert (taken / "mine.txt").is_file()
