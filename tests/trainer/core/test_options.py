"""Library functions take typed options: each command's parser and its options dataclass stay one and the same,
and no library module takes an ``argparse.Namespace``."""
from __future__ import annotations

import argparse
import ast
import dataclasses
from pathlib import Path

import pytest

from trainer.cli import build_parser
from trainer.core.options import options_dict, options_from
from trainer.depthfusion.config import FuseOptions, FusionEvalOptions, FusionTrainConfig
from trainer.experiments.config import BenchmarkOptions, BenchOptions, CurveOptions, ExperimentOptions
from trainer.seg.config import EvaluateOptions, PredictOptions, SegTrainConfig

ROOT = Path(__file__).resolve().parents[3]
OPTIONS = {"seg": SegTrainConfig, "evaluate": EvaluateOptions, "predict": PredictOptions,
           "sim2real": ExperimentOptions, "curve": CurveOptions, "benchmark": BenchmarkOptions,
           "bench": BenchOptions, "fusion": FusionTrainConfig, "fuse": FuseOptions, "fusion-eval": FusionEvalOptions}


def _subparser(name: str) -> argparse.ArgumentParser:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices[name]


def _parser_defaults(p: argparse.ArgumentParser) -> dict[str, object]:
    """dest -> default, as parsing an empty command line would give it (hidden aliases carry SUPPRESS)."""
    out: dict[str, object] = {}
    for a in p._actions:
        if a.dest == "help" or a.default == argparse.SUPPRESS and a.dest in out:
            continue
        if a.default != argparse.SUPPRESS or a.dest not in out:
            out[a.dest] = p._defaults.get(a.dest, a.default)
    out.update({k: v for k, v in p._defaults.items() if k != "func"})
    return out


def _field_default(f: dataclasses.Field) -> object:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return dataclasses.MISSING


@pytest.mark.parametrize("command", sorted(OPTIONS))
def test_every_flag_is_a_field_with_the_parsers_default(command):
    cls, parser = OPTIONS[command], _subparser(command)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    defaults = _parser_defaults(parser)
    assert set(defaults) <= set(fields), f"{command}: flags without a field: {set(defaults) - set(fields)}"
    for dest, default in defaults.items():
        if default == argparse.SUPPRESS:
            continue
        want = _field_default(fields[dest])
        if want is not dataclasses.MISSING:  # a required field: the parser requires the flag too
            assert want == default, f"{command} --{dest}: field default {want!r}, parser default {default!r}"


def test_options_from_reads_fields_only_and_applies_overrides():
    ns = argparse.Namespace(checkpoint="m.pt", data="d", func=print, no_such_flag=1)
    opts = options_from(EvaluateOptions, ns, threshold=0.3)
    assert (opts.checkpoint, opts.data, opts.threshold, opts.workers) == ("m.pt", "d", 0.3, 2)
    assert not hasattr(opts, "func") and not hasattr(opts, "no_such_flag")
    again = options_from(EvaluateOptions, options_dict(opts))  # a checkpoint's stored args round-trip
    assert again == opts
    with pytest.raises(TypeError):  # a required field missing is a programming error, not a default
        options_from(EvaluateOptions, argparse.Namespace(data="d"))


def test_a_parsed_command_line_becomes_its_options_unchanged():
    args = build_parser().parse_args(["seg", "--data", "shards", "--max-steps", "7", "--crop", "0", "--depth", "tof"])
    cfg = options_from(SegTrainConfig, args)
    assert (cfg.data, cfg.max_steps, cfg.crop, cfg.depth, cfg.valid_channel) == ("shards", 7, 0, "tof", None)
    curve = options_from(CurveOptions, build_parser().parse_args(["curve", "--real", "r", "--sizes", "0,5"]))
    assert curve.curve == "0,5" and curve.out == "runs/curve"


def _namespace_parameters(path: Path) -> list[str]:
    tree = ast.parse(path.read_text())
    hits = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for a in node.args.args + node.args.kwonlyargs:
                if a.annotation is not None and "Namespace" in ast.unparse(a.annotation):
                    hits.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name}({a.arg})")
    return hits


def test_no_library_function_takes_an_argparse_namespace():
    """Only the command layer (``trainer/commands``, ``trainer/cli.py``) sees parsed command lines."""
    libs = [p for p in (ROOT / "trainer").rglob("*.py")
            if "commands" not in p.parts and p.name != "cli.py"]
    assert libs
    hits = [h for p in libs for h in _namespace_parameters(p)]
    assert not hits, "library functions taking argparse.Namespace: " + "; ".join(hits)
