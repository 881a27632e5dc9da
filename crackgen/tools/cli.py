"""`crackgen` command line: generate, validate, inspect, bench, show, verify, export, adapt, stats, measure-check.

Each subcommand imports its heavy modules lazily so `crackgen --help` and
`crackgen validate` stay fast. Bad input exits 1 with one line per problem; a run
whose samples/shards failed (or whose worker died) exits 3 after its summary.
"""
from __future__ import annotations

import argparse
import json
import sys

from crackgen import __version__
from crackgen.cli_aliases import deprecated_alias
from crackgen.errors import path_error_line

EXIT_BAD_INPUT = 1
EXIT_RUN_FAILED = 3
BENCH_COMPONENTS = ("core", "materials", "sensors", "shards")
SET_HELP = "change a recipe field, e.g. crack.shape=fbm or camera.distance_m='{ min = 0.6, max = 1.2 }' (repeatable)"


def _err(msg: str) -> int:
    print(f"crackgen: {msg}", file=sys.stderr)
    return EXIT_BAD_INPUT


def _load(path: str, sets: list[str] | None = None):
    """The recipe (with any ``--set`` overrides), or None after printing its problems (one line each)."""
    from crackgen.config.recipe import RecipeError, load_recipe
    from crackgen.config.recipe_overrides import apply_sets

    try:
        return apply_sets(load_recipe(path), sets or [], path)
    except RecipeError as exc:
        for line in exc.problems:
            print(line, file=sys.stderr)
        return None


def _cmd_validate(args: argparse.Namespace) -> int:
    from crackgen.config.recipe import summary
    from crackgen.datagen.generate import GenerateError, check_inputs

    recipe = _load(args.recipe, args.set)
    if recipe is None:
        return EXIT_BAD_INPUT
    try:
        check_inputs(recipe)  # files the recipe points to, e.g. the [adapt] target photos
    except GenerateError as exc:
        return _err(str(exc))
    print(f"{args.recipe}: OK")
    print(summary(recipe))
    return 0


def _cmd_generate(args: argparse.Namespace) -> int:
    from crackgen.datagen.generate import GenerateError, GenerateOptions, generate, parse_storage_options

    recipe = _load(args.recipe, args.set)
    if recipe is None:
        return EXIT_BAD_INPUT
    try:
        opts = GenerateOptions(
            out=args.out, workers=args.workers, backend=args.backend, ray_address=args.ray_address,
            samples=args.samples, resume=args.resume, storage_options=parse_storage_options(args.storage_options),
            progress=not args.no_progress, worker_max_shards=args.worker_max_shards,
        )
        summary = generate(recipe, opts)
    except GenerateError as exc:
        return _err(str(exc))
    if args.json:
        print(json.dumps(summary.to_dict(), indent=1))
    else:
        for line in summary.lines():
            print(line)
    if summary.aborted:
        print(f"crackgen: aborted: {summary.aborted}; run again with --resume", file=sys.stderr)
    elif not summary.ok:
        print(f"crackgen: {len(summary.failures)} samples and {len(summary.shard_errors)} shards failed "
              "(listed in the manifest); --resume redoes them", file=sys.stderr)
    return 0 if summary.ok else EXIT_RUN_FAILED


def _cmd_bench_sweep(args: argparse.Namespace, recipe) -> int:
    from crackgen.tools.sweep import BenchSweepError, SweepOptions, format_rows, sweep
    from crackgen.tools.sweep_args import SweepError, build_settings, resolve

    for name in ("workers", "reference_samples"):
        if getattr(args, name) < 1:
            return _err(f"--{name.replace('_', '-')} must be >= 1, got {getattr(args, name)}")
    if args.dilate < 0 or args.first_index < 0:
        return _err(f"--dilate and --first-index must be >= 0, got {args.dilate} and {args.first_index}")
    try:
        settings = build_settings(args.sweep, args.combo, grid=args.grid)
        resolve(recipe, settings)  # every value checked before the first render
        opts = SweepOptions(samples=args.samples, first_index=args.first_index, reference_samples=args.reference_samples,
                            workers=args.workers, threads=args.threads, dilate_px=args.dilate,
                            cache_dir=args.cache or "", out=args.out)
        res = sweep(recipe, settings, opts, progress=not args.json)
    except (SweepError, BenchSweepError) as exc:
        return _err(str(exc))
    if args.json:
        print(json.dumps(res, indent=1))
    else:
        print(format_rows(res["rows"], res["header"]))
        print(f"wrote {', '.join(res['written'])}; references cached in {res['reference_cache']}")
    return 0


def _cmd_bench_component(args: argparse.Namespace) -> int:
    import importlib
    import shlex

    if args.recipe is not None:
        return _err(f"bench: give a recipe or --component, not both (got {args.recipe} and {args.component})")
    try:
        argv = shlex.split(args.component_args)
    except ValueError as exc:
        return _err(f"bench: --component-args: {exc}")
    try:
        rc = importlib.import_module(f"crackgen.tools.bench_{args.component}").main(argv)
    except SystemExit as exc:  # its own parser refused the arguments (it printed why)
        return EXIT_BAD_INPUT if exc.code else 0
    return rc or 0


def _cmd_bench(args: argparse.Namespace) -> int:
    from crackgen.datagen.heap import HeapSettingError, mmap_threshold_from_env
    from crackgen.tools.bench import bench, format_table

    if args.component:
        return _cmd_bench_component(args)
    if args.recipe is None:
        return _err("bench: give a RECIPE (or --component NAME)")
    recipe = _load(args.recipe)
    if recipe is None:
        return EXIT_BAD_INPUT
    if args.samples < 1:
        return _err(f"--samples must be >= 1, got {args.samples}")
    try:
        mmap_threshold_from_env()
    except HeapSettingError as exc:
        return _err(str(exc))
    if args.sweep or args.combo:
        return _cmd_bench_sweep(args, recipe)
    result = bench(recipe, samples=args.samples, threads=args.threads, progress=not args.json)
    print(json.dumps(result, indent=1) if args.json else format_table(result))
    return 0


def _cmd_inspect(args: argparse.Namespace) -> int:
    from crackgen.tools.gallery import InspectError, write_gallery

    try:
        index = write_gallery(args.dir, page_size=args.page_size, limit=args.limit)
    except InspectError as exc:
        return _err(str(exc))
    print(f"gallery: {index}")
    return 0


def _cmd_show(args: argparse.Namespace) -> int:
    from crackgen.tools.show import ShowError, show

    if not args.pointcloud and not args.png:
        return _err("show: give --pointcloud OUT.ply and/or --png OUT.png")
    try:
        lines = show(args.dir, args.key, pointcloud=args.pointcloud, png=args.png, source=args.depth)
    except ShowError as exc:
        return _err(str(exc))
    for line in lines:
        print(line)
    return 0


def _cmd_verify(args: argparse.Namespace) -> int:
    from crackgen.shards import verify_dataset

    problems = verify_dataset(args.dir, decode=not args.quick)
    for p in problems:
        print(p, file=sys.stderr)
    if problems:
        return EXIT_RUN_FAILED
    print(f"{args.dir}: OK")
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from crackgen.tools.export import ExportError, export

    try:
        result = export(args.dir, args.to, args.members.split(","), depth_format=args.depth_format,
                        progress=not args.no_progress)
    except ExportError as exc:
        return _err(str(exc))
    print(result.summary())
    return 0


def _cmd_adapt(args: argparse.Namespace) -> int:
    from crackgen.datagen.adapt_shards import AdaptShardsError, adapt_dataset, adapt_section

    try:
        section = adapt_section(args.target, args.method, args.weights, args.band, args.probability)
        summary = adapt_dataset(args.shards, args.out, section, seed=args.seed, resume=args.resume,
                                progress=not args.no_progress)
    except AdaptShardsError as exc:
        return _err(str(exc))
    print("\n".join(summary.lines()))
    return 0


def _cmd_stats(args: argparse.Namespace) -> int:
    from crackgen.tools.stats import StatsError, compute_stats, format_side_by_side, format_stats, write_json

    try:
        results = [compute_stats(p, limit=args.limit, progress=not args.no_progress) for p in args.path]
        print(format_stats(results[0]) if len(results) == 1 else format_side_by_side(results))
        if args.json:
            print(f"wrote {write_json(results[0] if len(results) == 1 else results, args.json)}")
    except StatsError as exc:
        return _err(str(exc))
    return 0


def _cmd_measure_check(args: argparse.Namespace) -> int:
    from crackgen.tools.measure_check import MeasureCheckError, format_check, measure_check, write_json

    try:
        result = measure_check(args.path, limit=args.limit, progress=not args.no_progress)
        print(format_check(result))
        if args.json:
            print(f"wrote {write_json(result, args.json)}")
    except MeasureCheckError as exc:
        return _err(str(exc))
    return 0


def _add_generate(sub: argparse._SubParsersAction) -> None:
    from crackgen.datagen.backends import BACKENDS  # the --backend choices (registry keys)

    g = sub.add_parser("generate", help="render a dataset of shards from a recipe")
    g.add_argument("recipe")
    g.add_argument("--out", required=True, help="output directory or fsspec URL (s3://bucket/path)")
    g.add_argument("--workers", type=int, default=1, help="worker processes (local) or CPUs (local Ray); default 1")
    g.add_argument("--backend", choices=tuple(BACKENDS), default="local", help="local process pool or Ray tasks")
    g.add_argument("--ray-address", default=None, help="Ray cluster address (default: start a local Ray)")
    g.add_argument("--samples", type=int, default=None, help="override dataset.samples (changes the recipe hash)")
    g.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help=SET_HELP)
    g.add_argument("--resume", action="store_true", help="continue a dataset: keep verified shards, redo the rest")
    g.add_argument("--storage-options", default=None,
                   help="fsspec storage options as JSON (default: $CRACKGEN_STORAGE_OPTIONS)")
    g.add_argument("--worker-max-shards", type=int, default=0, metavar="K",
                   help="replace each worker process with a fresh one after K shards, so a long run's memory "
                        "stays at what one worker reaches in K shards (0 = never, the default)")
    g.add_argument("--no-progress", action="store_true", help="no progress bar")
    g.add_argument("--json", action="store_true", help="print the summary as JSON")
    g.set_defaults(func=_cmd_generate)


def _add_validate(sub: argparse._SubParsersAction) -> None:
    v = sub.add_parser("validate", help="check a recipe and print its summary")
    v.add_argument("recipe")
    v.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help=SET_HELP)
    v.set_defaults(func=_cmd_validate)


def _add_inspect(sub: argparse._SubParsersAction) -> None:
    i = sub.add_parser("inspect", help="write an HTML gallery DIR/inspect/index.html and a contact sheet")
    i.add_argument("dir")
    i.add_argument("--page-size", type=int, default=24, help="samples per gallery page")
    i.add_argument("--limit", type=int, default=None, help="at most this many samples")
    i.set_defaults(func=_cmd_inspect)


def _add_bench(sub: argparse._SubParsersAction) -> None:
    b = sub.add_parser("bench", help="per-stage timing table of the sample pipeline, or of one component")
    b.add_argument("recipe", nargs="?", default=None)
    b.add_argument("--component", choices=BENCH_COMPONENTS, default=None,
                   help="time one component alone instead of a recipe: the numpy core (crack map, skeleton, "
                        "measurement, mesh), material maps, sensors or shard I/O")
    b.add_argument("--component-args", default="", metavar="'ARGS'",
                   help="options of that component's benchmark, e.g. --component core --component-args='--px 512' (write = before a value that starts with -)")
    b.add_argument("--samples", type=int, default=5, help="timed samples (after one warm-up sample)")
    b.add_argument("--threads", type=int, default=0,
                   help="Cycles threads (0 = recipe value, else all cores; with --sweep: per worker, 0 = cores / workers)")
    b.add_argument("--json", action="store_true", help="machine-readable output")
    b.add_argument("--sweep", action="append", default=[], metavar="KEY=V1,V2",
                   help="time and compare these values of a dotted recipe key (one at a time around the recipe), "
                        "or layout=WxT (W workers of T threads); repeatable")
    b.add_argument("--combo", action="append", default=[], metavar="'K=V K=V'",
                   help="one extra setting changing several keys together; repeatable")
    b.add_argument("--grid", action="store_true", help="--sweep axes as a full grid instead of one at a time")
    b.add_argument("--reference-samples", type=int, default=256, help="sweep: spp of the reference (no denoiser)")
    b.add_argument("--workers", type=int, default=1, help="sweep: worker processes of every setting without a layout")
    b.add_argument("--first-index", type=int, default=0, help="sweep: first sample index")
    b.add_argument("--dilate", type=int, default=3, help="sweep: crack region = GT crack mask grown by this (px)")
    b.add_argument("--cache", default=None, help="sweep: reference cache folder (default ~/.cache/crackgen/bench_refs)")
    b.add_argument("--out", default="bench_sweep", help="sweep: folder for sweep.csv, sweep.json, sweep.md")
    b.set_defaults(func=_cmd_bench)


def _add_show(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("show", help="coloured point cloud (and a PNG view) of one sample")
    s.add_argument("dir")
    s.add_argument("key", help="sample key, e.g. 000000-00001")
    s.add_argument("--pointcloud", default=None, help="write a .ply point cloud")
    s.add_argument("--png", default=None, help="write a rendered view of the point cloud")
    s.add_argument("--depth", choices=("depth", "tof", "lidar"), default="depth", help="which depth map to lift")
    s.set_defaults(func=_cmd_show)


def _add_verify(sub: argparse._SubParsersAction) -> None:
    c = sub.add_parser("verify", help="check every shard against the manifest (size, sha256, decodes)")
    c.add_argument("dir")
    c.add_argument("--quick", action="store_true", help="size and sha256 only, do not decode members")
    c.set_defaults(func=_cmd_verify)


def _add_export(sub: argparse._SubParsersAction) -> None:
    e = sub.add_parser("export", help="images/ + masks/ (+ depth/, tof/, lidar/) folders for other tools")
    e.add_argument("dir")
    e.add_argument("--to", required=True, help="output folder (must be new or empty)")
    e.add_argument("--members", default="rgb,mask", help="comma list of rgb, mask, depth, tof, lidar")
    e.add_argument("--depth-format", choices=("png16", "exr"), default="png16",
                   help="png16: 16-bit PNG in mm, 0 = none; exr: float32 metres, -1 = none")
    e.add_argument("--no-progress", action="store_true", help="no progress bar")
    e.set_defaults(func=_cmd_export)


def _add_adapt(sub: argparse._SubParsersAction) -> None:
    a = sub.add_parser("adapt", help="adapt the RGB views of rendered shards toward unlabeled photos (new shards)")
    a.add_argument("shards", help="source dataset directory (a finished crackgen dataset)")
    a.add_argument("--target", required=True, help="folder of unlabeled target photos")
    a.add_argument("--out", required=True, help="new dataset directory")
    a.add_argument("--method", default="fourier,reinhard,histogram",
                   help="fourier, reinhard and/or histogram; several: one drawn per sample")
    a.add_argument("--weights", default=None, help="draw weights of --method (default: equal)")
    a.add_argument("--band", default="0.005,0.05", help="fourier band MIN,MAX (fraction of min(H, W))")
    a.add_argument("--probability", type=float, default=1.0, help="chance that a sample is adapted")
    a.add_argument("--seed", type=int, default=None, help="seed of the draws (default: the source recipe's)")
    a.add_argument("--resume", action="store_true", help="keep verified output shards, redo the rest")
    a.add_argument("--no-progress", action="store_true", help="no progress bar")
    a.set_defaults(func=_cmd_adapt)


def _add_stats(sub: argparse._SubParsersAction) -> None:
    st = sub.add_parser("stats", help="crack width, pixel fraction, components and image statistics "
                                      "of shards or an images/ + masks/ folder")
    st.add_argument("path", metavar="DIR|FOLDER", nargs="+",
                    help="a crackgen dataset, or a folder with images/ and masks/; several: one table side by side")
    st.add_argument("--json-out", dest="json", default=None, metavar="OUT", help="also write the statistics as JSON")
    deprecated_alias(st, "--json", "--json-out", "crackgen")
    st.add_argument("--limit", type=int, default=None, help="at most this many images")
    st.add_argument("--no-progress", action="store_true", help="no progress bar")
    st.set_defaults(func=_cmd_stats)


def _add_measure_check(sub: argparse._SubParsersAction) -> None:
    mc = sub.add_parser("measure-check", help="crack length/width measured from each rendered mask + depth + K "
                                              "against the sample's 'visible' GT: median and p90 relative error")
    mc.add_argument("path", metavar="DIR", help="a crackgen dataset (e.g. made from recipes/measure.toml)")
    mc.add_argument("--json-out", dest="json", default=None, metavar="OUT",
                    help="also write per-sample figures and the summary as JSON")
    deprecated_alias(mc, "--json", "--json-out", "crackgen")
    mc.add_argument("--limit", type=int, default=None, help="at most this many samples")
    mc.add_argument("--no-progress", action="store_true", help="no progress bar")
    mc.set_defaults(func=_cmd_measure_check)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="crackgen", description="Synthetic RGB-D crack datasets from headless Blender.")
    p.add_argument("--version", action="version", version=f"crackgen {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for add in (_add_generate, _add_validate, _add_inspect, _add_bench, _add_show, _add_verify, _add_export,
                _add_adapt, _add_stats, _add_measure_check):
        add(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    from fusion.errors import FusionError

    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except FusionError as exc:  # bad geometry or sensor input that no command-specific check caught first
        return _err(str(exc))
    except OSError as exc:
        if not exc.filename:  # not about a path the user gave: a defect, keep its traceback
            raise
        return _err(path_error_line(exc))  # e.g. an output under a file or a dangling link
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
