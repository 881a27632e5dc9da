"""`crackgen measure-check`: the camera-view measurement against each sample's `visible` GT."""
import json

import numpy as np
import pytest

from crackgen.shards import ShardWriter, sample_key
from crackgen.tools.cli import main

F, W, H = 200.0, 96, 64
K = [[F, 0, W / 2 - 0.5], [0, F, H / 2 - 0.5], [0, 0, 1]]


def _sample(length_px: int, width_px: int, visible: dict) -> dict:
    """A fronto-parallel wall at 1 m (5 mm pixels) with one horizontal crack."""
    mask = np.zeros((H, W), np.uint8)
    mask[30:30 + width_px, 10:10 + length_px] = 255
    meta = {"cameras": {"rgb": {"K": K}}, "crack": {"shape": "fracture"}, "visible": visible}
    return {"rgb.png": np.zeros((H, W, 3), np.uint8), "mask.png": mask,
            "depth.exr": np.ones((H, W), np.float32), "json": meta}


def _gt(length_m, width_m):
    return {"texels": 100, "longest_path_m": length_m, "tip_to_tip_sum_m": length_m, "total_length_m": length_m,
            "mean_width_m": width_m, "max_width_m": width_m, "components": [{}]}


def test_measure_check_reports_errors(tmp_path, capsys):
    root = tmp_path / "ds"
    with ShardWriter(root, 0) as w:
        # 71 px between the end pixels' centres at 5 mm: 0.355 m; 4 px = 2 cm wide. GT exact, then 10 % long.
        w.add(sample_key(0, 0), _sample(72, 4, _gt(0.355, 0.02)))
        w.add(sample_key(0, 1), _sample(72, 4, _gt(0.355 / 1.1, 0.02)))
        w.add(sample_key(0, 2), _sample(72, 4, {"texels": 0, "components": []}))  # nothing in view: skipped
    out = tmp_path / "check.json"
    assert main(["measure-check", str(root), "--json-out", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "2 samples checked (1 without a visible crack skipped)" in text
    res = json.loads(out.read_text())
    errs = sorted(abs(r["measured"]["longest_path"] - r["gt"]["longest_path"]) / r["gt"]["longest_path"]
                  for r in res["per_sample"])
    assert errs[0] < 0.01 and errs[1] == pytest.approx(0.1, abs=0.01)
    assert res["errors"]["mean_width"]["median"] < 0.05


def test_measure_check_needs_visible_gt(tmp_path, capsys):
    root = tmp_path / "old"
    with ShardWriter(root, 0) as w:
        s = _sample(40, 3, {})
        del s["json"]["visible"]
        w.add(sample_key(0, 0), s)
    assert main(["measure-check", str(root), "--no-progress"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no 'visible' GT" in err[0]
