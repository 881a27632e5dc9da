"""`crackgen bench --sweep`: argument parsing, recipe overrides, reference cache, rows and files."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from crackgen.config.recipe import Recipe
from crackgen.tools import sweep as sw
from crackgen.tools.sweep_args import (
    Layout,
    SweepError,
    apply_overrides,
    build_settings,
    parse_combo,
    parse_sweep,
    parse_value,
    resolve,
)


@pytest.mark.parametrize("text,value", [("on", True), ("TRUE", True), ("off", False), ("false", False), ("8", 8),
                                        ("-2", -2), ("0.05", 0.05), ("1e-3", 1e-3), ("fast", "fast")])
def test_values_are_typed(text, value):
    v = parse_value(text)
    assert v == value and type(v) is type(value)


def test_sweep_and_combo_parse_keys_values_and_layouts():
    assert parse_sweep("render.samples=8,16,32") == ("render.samples", [8, 16, 32])
    assert parse_sweep("layout=1x2,2x1") == ("layout", [Layout(1, 2), Layout(2, 1)])
    assert parse_combo("render.samples=16 render.denoise=off") == {"render.samples": 16, "render.denoise": False}


@pytest.mark.parametrize("sweep,combo,problem", [
    (["render.samples"], [], "expected KEY=VALUE"),
    (["render.samples=8,,16"], [], "empty value"),
    (["layout=2by1"], [], "layout must be WORKERSxTHREADS"),
    (["layout=0x2"], [], "layout must be"),
    (["render.samples=8", "render.samples=16"], [], "given twice"),
    ([], ["render.samples=8,16"], "one value per key in a combo"),
    ([], ["   "], "no KEY=VALUE pairs"),
])
def test_bad_arguments_are_one_line_errors(sweep, combo, problem):
    with pytest.raises(SweepError, match=problem) as exc:
        build_settings(sweep, combo)
    assert "\n" not in str(exc.value)


def test_one_at_a_time_grid_and_combos():
    s = build_settings(["render.samples=8,16", "render.denoise=on,off"], ["render.samples=8 layout=2x1"])
    assert [x.label for x in s] == ["baseline", "render.samples=8", "render.samples=16", "render.denoise=on",
                                    "render.denoise=off", "render.samples=8 layout=2x1"]
    assert s[-1].overrides == {"render.samples": 8} and s[-1].layout == Layout(2, 1)
    g = build_settings(["render.samples=8,16", "render.denoise=on,off"], [], grid=True)
    assert len(g) == 1 + 4 and g[1].overrides == {"render.samples": 8, "render.denoise": True}


def test_overrides_make_a_validated_recipe_and_keep_the_rest():
    base = Recipe()
    r = apply_overrides(base, {"render.samples": 8, "material.texture_px": 512, "crack.depth_m": 0.01,
                               "render.denoise_prefilter": "fast"})
    assert (r.render.samples, r.material.texture_px, r.render.denoise_prefilter) == (8, 512, "fast")
    assert r.crack.depth_m.value == 0.01
    assert r.camera == base.camera and apply_overrides(base, {}).hash == base.hash


@pytest.mark.parametrize("key,value,problem", [
    ("render.sample", 8, "unknown key 'render.sample'"),
    ("rendr.samples", 8, "no 'rendr' in recipe"),
    ("render", 8, "is a section"),
    ("render.samples", "many", "render.samples: Input should be a valid integer"),
    ("render.denoise_prefilter", "slow", "render.denoise_prefilter: Input should be"),
    ("surface.grid_px", 2, "surface.grid_px: Input should be greater than or equal to 8"),
])
def test_unknown_keys_and_bad_values_name_the_setting(key, value, problem):
    with pytest.raises(SweepError, match=problem) as exc:
        resolve(Recipe(), build_settings([f"{key}={value}"], []))
    assert str(exc.value).startswith(f"setting '{key}=") and "\n" not in str(exc.value)


def _fake_run(calls):
    def run(recipe, indices, layout, cores, warmup=True, keep_mask=False, on_sample=None, name=""):
        calls.append((name, list(indices), recipe.render.samples, recipe.render.denoise))
        rng = np.random.default_rng(recipe.render.samples)
        renders = {i: np.full((8, 8, 3), 0.5, np.float32) + rng.normal(0, 0.1 / recipe.render.samples, (8, 8, 3))
                   .astype(np.float32) for i in indices}
        masks = {i: np.pad(np.full((2, 2), 255, np.uint8), 3) for i in indices}
        return sw.RunResult(renders, masks, {i: 2.0 for i in indices}, {i: 1.5 for i in indices}, 4.0 * len(indices),
                            1.0, Layout(layout.workers, layout.threads or cores))
    return run


def test_sweep_caches_references_and_writes_rows(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(sw, "run_renders", _fake_run(calls))
    opts = sw.SweepOptions(samples=2, reference_samples=64, cache_dir=str(tmp_path / "cache"), out=str(tmp_path / "out"),
                           cores=2)
    settings = build_settings(["render.samples=4", "layout=2x1"], [])
    res = sw.sweep(Recipe(), settings, opts, progress=False)
    assert calls[0] == ("reference", [0, 1], 64, False)  # 256-style reference: no denoiser
    assert [r["setting"] for r in res["rows"]] == ["baseline", "render.samples=4", "layout=2x1"]
    assert res["rows"][2]["layout"] == "2x1" and res["rows"][0]["layout"] == "1x2"
    row = res["rows"][1]
    assert row["s_per_sample"] == pytest.approx(4.0) and row["cycles_share"] == pytest.approx(0.75)
    assert res["rows"][1]["psnr"] < res["rows"][0]["psnr"]  # 4 spp noisier than the 16 spp baseline
    assert row["crack_mae"] > 0 and math.isfinite(row["crack_psnr"])
    saved = json.loads((tmp_path / "out" / "sweep.json").read_text())
    assert [r["setting"] for r in saved["rows"]] == [r["setting"] for r in res["rows"]]
    assert (tmp_path / "out" / "sweep.csv").read_text().count("\n") == 4
    assert "| `render.samples=4` | 1x2 |" in (tmp_path / "out" / "sweep.md").read_text()
    assert sorted(p.name for p in (tmp_path / "out" / "previews").iterdir()) == [
        "baseline_000000.png", "layout=2x1_000000.png", "reference_000000.png", "render.samples=4_000000.png"]
    calls.clear()
    sw.sweep(Recipe(), settings[:1], opts, progress=False)
    assert [c[0] for c in calls] == ["baseline"]  # references came from the cache


def test_sweep_runs_keep_the_same_crack_under_any_label_policy():
    r = apply_overrides(Recipe(), {"label.invisible": "redraw"})
    assert apply_overrides(r, sw.SWEEP_FIXED).label.invisible == "keep"


@pytest.mark.parametrize("argv,problem", [
    (["--sweep", "render.sample=8"], "crackgen: setting 'render.sample=8': unknown key 'render.sample'"),
    (["--combo", "render.samples=x"], "crackgen: setting 'render.samples=x': render.samples: Input should be"),
    (["--sweep", "render.samples=8", "--workers", "0"], "crackgen: --workers must be >= 1, got 0"),
])
def test_cli_refuses_a_bad_sweep_before_rendering(tmp_path, capsys, argv, problem):
    from crackgen.tools.cli import main

    recipe = tmp_path / "r.toml"
    recipe.write_text("[render]\nsamples = 4\n")
    assert main(["bench", str(recipe), "--out", str(tmp_path / "out"), *argv]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith(problem) and "\n" not in err
    assert not (tmp_path / "out").exists()
