"""Data in and out: read_uff against pyuff (independent reader), simulate, the laws, and
errors that name the key."""

from __future__ import annotations

import numpy as np
import polars as pl
import pytest

import rfmlab
from conftest import STUDIES, study_copy


def test_read_uff_equals_pyuff():
    pyuff = pytest.importorskip("pyuff")
    path = STUDIES / "data" / "paper_virtual_L1.uff"
    df = rfmlab.read_uff(path)
    assert set(df["level"].unique()) == {"L1"}
    assert df["quantity"].unique().to_list() == ["accelerance"]
    sets = pyuff.UFF(str(path)).read_sets()
    frfs = [s for s in sets if s["type"] == 58 and s["func_type"] == 4]
    assert len(frfs) == df["response_id"].n_unique() == 4
    for s in frfs:
        ch = df.filter(pl.col("response_id") == s["rsp_node"]).sort("freq_hz")
        np.testing.assert_allclose(ch["freq_hz"].to_numpy(), s["x"], rtol=1e-12)
        np.testing.assert_allclose(ch["re"].to_numpy(), np.real(s["data"]), rtol=1e-6, atol=1e-12)
        np.testing.assert_allclose(ch["im"].to_numpy(), np.imag(s["data"]), rtol=1e-6, atol=1e-12)
    assert df["coherence"].null_count() == 0
    assert 0 < df["coherence"].min() and df["coherence"].max() <= 1


def test_simulate_reproduces_the_bundled_data(tmp_path):
    """The bundled paper data were written by `rfmlab simulate studies/data/paper_experiment.toml`;
    simulating the file again gives the same H1 (same seed) and the sidecar's truth."""
    sim = rfmlab.simulate(STUDIES / "data" / "paper_experiment.toml", out=tmp_path / "v.uff")
    assert sim.truth["simulated"] is True and sim.truth["levels"][0]["law"] == "model4"
    assert sorted(p.split("/")[-1] for p in sim.files) == ["v.truth.json", "v_L1.uff", "v_L2.uff"]
    bundled = rfmlab.read_uff(STUDIES / "data" / "paper_virtual_L1.uff")
    mine = sim.data.filter(pl.col("level") == "L1")
    key = ["response_id", "freq_hz"]
    j = bundled.join(mine, on=key, suffix="_sim").sort(key)
    assert j.height == bundled.height
    np.testing.assert_allclose(j["re_sim"], j["re"], rtol=1e-6, atol=1e-9 * np.abs(j["re"]).max())
    np.testing.assert_allclose(j["im_sim"], j["im"], rtol=1e-6, atol=1e-9 * np.abs(j["im"]).max())
    # What was written reads back as what was returned.
    back = rfmlab.read_uff(tmp_path / "v_L1.uff").sort(key)
    np.testing.assert_allclose(back["re"], mine.sort(key)["re"], rtol=1e-6)


def test_modulus_of_model4_is_its_formula():
    """Model 4: E* = E0 + j h + j w eta1 E1 / (E1 + j w eta1)."""
    p = {"E0": 6e6, "h": 1e6, "E1": 3e6, "eta1": 3e3}
    f = np.array([1.0, 20.0, 400.0])
    w = 2 * np.pi * f
    want = p["E0"] + 1j * p["h"] + 1j * w * p["eta1"] * p["E1"] / (p["E1"] + 1j * w * p["eta1"])
    np.testing.assert_allclose(rfmlab.modulus("model4", p, f), want, rtol=1e-12)
    assert [n for n, _ in rfmlab.law_parameters("model4")] == ["E0", "h", "E1", "eta1"]


def test_bad_key_raises_study_error_naming_it(tmp_path):
    path = study_copy(tmp_path, "default.toml", "bad", {"band_hz = [1.0, 500.0]": "band_hz = [500.0, 1.0]"})
    with pytest.raises(rfmlab.StudyError) as e:
        rfmlab.load(path)
    assert e.value.key == "measurements.band_hz", e.value.key
    assert e.value.file == str(path)
    assert e.value.message and e.value.fix


def test_unknown_key_and_missing_data_name_their_keys(tmp_path):
    path = study_copy(tmp_path, "default.toml", "typo", {"[structure.beam]\n": "[structure.beam]\nthicknes = 0.010\n"})
    with pytest.raises(rfmlab.StudyError) as e:
        rfmlab.load(path)
    assert "thicknes" in e.value.key or "thicknes" in e.value.message, (e.value.key, e.value.message)
    path = study_copy(tmp_path, "default.toml", "nodata", {"paper_virtual_L2.uff": "missing_L2.uff"})
    # Checked when loading (or, for data found only when running, by run()).
    with pytest.raises(rfmlab.StudyError) as e:
        rfmlab.load(path).run()
    assert e.value.key == "measurements.levels[1].files[0]", e.value.key
    with pytest.raises(rfmlab.StudyError) as e:
        rfmlab.load(tmp_path / "absent.toml")
    assert e.value.key == "(file)"
