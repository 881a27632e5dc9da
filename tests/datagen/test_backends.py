"""Back-end registry and import structure of crackgen.datagen (no rendering).

The layering is: tasks (shard work unit) <- backends (where shards run) <- generate
(driver). Importing the driver or the per-sample pipeline must stay free of bpy, so a
process that only plans, writes manifests or reads shards never loads Blender.
"""
from __future__ import annotations

import subprocess
import sys

import pytest
from tiny_recipes import tiny_recipe

from crackgen.config.recipe import parse_recipe
from crackgen.datagen.backends import BACKENDS, Backend, LocalBackend, RayBackend
from crackgen.datagen.generate import GenerateError, GenerateOptions, generate
from crackgen.tools.cli import build_parser


def _modules_after_import(*modules: str) -> set[str]:
    """sys.modules of a fresh interpreter after importing ``modules`` (no leaks from this test run)."""
    code = "import sys\n" + "".join(f"import {m}\n" for m in modules) + "print('\\n'.join(sys.modules))"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    return set(res.stdout.split())


def test_registry_builds_every_backend_with_an_address():
    assert set(BACKENDS) == {"local", "ray"}
    for name, make in BACKENDS.items():
        backend: Backend = make(None)
        assert callable(backend.run), name
    assert isinstance(BACKENDS["local"](None), LocalBackend)
    ray = BACKENDS["ray"]("10.0.0.1:6379")
    assert isinstance(ray, RayBackend) and ray.address == "10.0.0.1:6379"


def test_unknown_backend_is_one_line_listing_the_choices(tmp_path):
    out = tmp_path / "out"
    with pytest.raises(GenerateError) as err:
        generate(parse_recipe(tiny_recipe(1)), GenerateOptions(out=str(out), backend="slurm", progress=False))
    msg = str(err.value)
    assert "\n" not in msg and "'slurm'" in msg
    assert all(name in msg for name in BACKENDS)
    assert not out.exists()  # refused before any work started


def test_cli_backend_choices_are_the_registry_keys():
    gen = build_parser()._subparsers._group_actions[0].choices["generate"]
    (action,) = [a for a in gen._actions if a.dest == "backend"]
    assert tuple(action.choices) == tuple(BACKENDS)


def test_driver_and_pipeline_import_without_bpy_or_ray():
    loaded = _modules_after_import("crackgen.datagen.generate", "crackgen.datagen.pipeline")
    assert {"crackgen.datagen.generate", "crackgen.datagen.pipeline"} <= loaded
    leaked = {m for m in loaded if m.split(".")[0] in ("bpy", "ray") or m.startswith("crackgen.blender")}
    assert not leaked, sorted(leaked)


def test_tasks_sit_below_driver_and_backends():
    loaded = _modules_after_import("crackgen.datagen.tasks")
    assert not {"crackgen.datagen.generate", "crackgen.datagen.backends", "crackgen.datagen.pipeline"} & loaded
    loaded = _modules_after_import("crackgen.datagen.backends")
    assert "crackgen.datagen.generate" not in loaded
