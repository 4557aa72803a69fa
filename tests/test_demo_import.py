"""`bayes-amb demo --import-formats`: every format identifies like the canonical CSV.

In the default suite (11 s): marked slow, it was not run, and the command the user guide
gives crashed for a while unseen (it read the summary as a dict after it became typed)."""

from __future__ import annotations

import json

from tests.helpers import run_cli


def test_import_demo_step(tmp_path, capsys):
    code, out, err = run_cli(["demo", "--import-formats", "--out", str(tmp_path), "--json"],
                             capsys)
    assert code == 0, err
    res = json.loads(out)
    assert set(res["formats"]) == {"mat", "mat73", "tdms", "hdf5", "csv"}
    for fmt, r in res["formats"].items():
        assert r["max_shift_in_sd"] < 0.1, fmt
        for n, true in (("k_By", 0.3), ("c_By", 0.2)):
            p = r["posterior"][n]
            assert abs(p["mean"] - true) < 4 * p["sd"], (fmt, n, p)
    assert res["controller"]["iso14839_zone"] == "A"
    assert res["controller"]["spectral_radius_full"] < 1
    assert json.loads((tmp_path / "import_demo.json").read_text())["formats"].keys() == \
        res["formats"].keys()
