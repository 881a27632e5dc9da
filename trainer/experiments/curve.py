"""The label-efficiency curve: how many real labels does synthetic pretraining save?

For each N in ``--curve`` (e.g. 0,10,30,60,120,180) and each repeat, two arms train
with the same step budget on the same N labelled real photos:

- ``real``: from scratch on the N photos (N = 0 has nothing to learn from: not run);
- ``finetune``: from that repeat's own synthetic-pretrained checkpoint (pretrained with the
  repeat's seed, so N = 0 has a spread too), fine-tuned on the N photos (N = 0 is the
  pretrained model itself, evaluated as it is).

Both arms are treated alike: the same steps, precise BN at the end (``trainer.seg.precise_bn``: at
a short budget the BatchNorm running statistics still lag the weights), and each model's
threshold chosen on the validation split. Each point records its own steps and its total
steps including pretraining; the spread over repeats is the sample standard deviation.

Subsets are nested (the 10 are inside the 30, ...): one seeded permutation of the
training split per repeat, and subset N is its first N names. They never touch the
test split because they are drawn from the training names only. This module holds
the pure parts (subsets, aggregation, headline, CSV, plot); ``trainer.experiments.sim2real``
runs the trainings.
"""
from __future__ import annotations

import csv
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from trainer.core.errors import TrainerInputError

ARMS = ("real", "finetune")


def parse_sizes(text: str) -> list[int]:
    """``"0,10,30"`` -> [0, 10, 30] (sorted, unique, each >= 0)."""
    try:
        sizes = sorted({int(t) for t in text.split(",") if t.strip()})
    except ValueError:
        raise TrainerInputError(f"--sizes: expected comma-separated photo counts, got {text!r}") from None
    if not sizes or sizes[0] < 0:
        raise TrainerInputError(f"--sizes: counts must be >= 0, got {text!r}")
    return sizes


def nested_subsets(train_names: Sequence[str], sizes: Iterable[int], seed: int, repeat: int) -> dict[int, list[str]]:
    """Subset of each size for one repeat: the first N of one seeded permutation (so nested)."""
    ordered = sorted(train_names)
    sizes = sorted(sizes)
    if sizes and sizes[-1] > len(ordered):
        raise TrainerInputError(f"--curve: {sizes[-1]} photos asked for, the training split has {len(ordered)}")
    perm = np.random.default_rng(np.random.SeedSequence([int(seed), 0xC0DE, int(repeat)])).permutation(len(ordered))
    chosen = [ordered[i] for i in perm]
    return {n: sorted(chosen[:n]) for n in sizes}


@dataclass
class CurvePoint:
    """One trained-and-evaluated model on the curve.

    ``f1``, ``precision``, ``recall`` and ``iou`` are on the test split at ``threshold`` (chosen on
    validation); ``cross`` holds F1 on each extra set at the same threshold (CSV columns ``f1:NAME``).
    ``steps`` are this model's own, ``total_steps`` include its pretraining.
    """

    n: int
    repeat: int
    arm: str
    f1: float
    precision: float
    recall: float
    iou: float
    threshold: float
    f1_at_05: float
    oracle_f1: float
    steps: int
    total_steps: int
    seconds: float
    cross: dict[str, float] = field(default_factory=dict)


CROSS_PREFIX = "f1:"


def write_csv(points: Sequence[CurvePoint], path: Path) -> None:
    fields = [k for k in CurvePoint.__dataclass_fields__ if k != "cross"]
    extra = list(dict.fromkeys(CROSS_PREFIX + name for p in points for name in p.cross))
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields + extra)
        w.writeheader()
        for p in points:
            row = asdict(p)
            cross = row.pop("cross")
            w.writerow(row | {CROSS_PREFIX + k: v for k, v in cross.items()})


def read_csv(path: Path) -> list[CurvePoint]:
    """Points of an earlier (possibly interrupted) curve in ``path``; [] when there is none."""
    if not path.is_file():
        return []
    types = {k: f.type for k, f in CurvePoint.__dataclass_fields__.items() if k != "cross"}
    cast = {"int": int, "float": float, "str": str}
    with open(path, newline="") as f:
        try:
            return [CurvePoint(**{k: cast[str(types[k])](row[k]) for k in types},
                               cross={k[len(CROSS_PREFIX):]: float(v) for k, v in row.items()
                                      if k.startswith(CROSS_PREFIX) and v not in ("", None)})
                    for row in csv.DictReader(f)]
        except (KeyError, ValueError) as exc:
            raise TrainerInputError(f"{path}: not a curve CSV written by cracktrain ({exc}); use a new --out") from None


def _stats(v: Sequence[float]) -> dict[str, float]:
    """Mean, sample standard deviation (ddof 1; 0 for one value, shown as n=1), min, max, count."""
    return {"mean": float(np.mean(v)), "std": float(np.std(v, ddof=1)) if len(v) > 1 else 0.0,
            "min": float(np.min(v)), "max": float(np.max(v)), "count": len(v)}


def summarise(points: Sequence[CurvePoint], metric: str = "f1") -> dict[str, dict[int, dict[str, float]]]:
    """arm -> N -> {mean, std (sample), min, max, count} of ``metric`` over the repeats; ``metric`` is a
    CurvePoint field or ``f1:NAME`` for an extra set."""
    out: dict[str, dict[int, dict[str, float]]] = {}
    for arm in ARMS:
        by_n: dict[int, list[float]] = {}
        for p in points:
            if p.arm != arm:
                continue
            v = p.cross.get(metric[len(CROSS_PREFIX):]) if metric.startswith(CROSS_PREFIX) else getattr(p, metric)
            if v is not None:
                by_n.setdefault(p.n, []).append(v)
        out[arm] = {n: _stats(v) for n, v in sorted(by_n.items())}
    return out


def labels_to_match(real_curve: dict[int, dict[str, float]], target_f1: float) -> float | None:
    """Photos real-only needs to reach ``target_f1``: linear interpolation of its mean curve
    between the two sizes that straddle the target; None if it never gets there."""
    pts = sorted((n, s["mean"]) for n, s in real_curve.items())
    if not pts:
        return None
    if pts[0][1] >= target_f1:
        return float(pts[0][0])
    for (n0, f0), (n1, f1) in zip(pts, pts[1:]):
        if f0 < target_f1 <= f1:
            return float(n0 + (target_f1 - f0) * (n1 - n0) / (f1 - f0))
    return None


def headline(summary: dict[str, dict[int, dict[str, float]]], at: int = 30) -> str:
    """'real-only needs N photos to match synthetic -> fine-tune with 30' (the curve's one number)."""
    ft = summary.get("finetune", {}).get(at)
    if ft is None:
        return f"no fine-tune point at N = {at}: add {at} to --curve for the headline"
    need = labels_to_match(summary.get("real", {}), ft["mean"])
    largest = max(summary.get("real", {0: None}), default=0)
    if need is None:
        return (f"synthetic -> fine-tune with {at} real photos reaches F1 {ft['mean']:.3f}; "
                f"real-only does not reach it with up to {largest} photos")
    saved = f" ({need / at:.1f}x the labels)" if at > 0 else ""
    return (f"synthetic -> fine-tune with {at} real photos reaches F1 {ft['mean']:.3f}; "
            f"real-only needs about {math.ceil(need)} photos to match it{saved}")


def table_lines(summary: dict[str, dict[int, dict[str, float]]], what: str = "F1") -> list[str]:
    sizes = sorted({n for arm in summary.values() for n in arm})
    lines = [f"| N real photos | real-only {what} (mean ± sd) | synthetic -> fine-tune {what} (mean ± sd) |",
             "|---|---|---|"]
    for n in sizes:
        cells = []
        for arm in ARMS:
            s = summary.get(arm, {}).get(n)
            cells.append("n/a" if s is None else f"{s['mean']:.3f} ± {s['std']:.3f} (n={s['count']})")
        lines.append(f"| {n} | {cells[0]} | {cells[1]} |")
    return lines


def plot_curve(summary: dict[str, dict[int, dict[str, float]]], path: Path, title: str,
               cross: dict[str, dict[str, dict[int, dict[str, float]]]] | None = None) -> None:
    """F1 against N per arm: mean line, min..max band over the repeats (matplotlib Agg); extra sets as thin
    dashed lines (fine-tune) and dotted lines (real-only) of their means."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4), dpi=120)
    for arm, label in (("real", "real only"), ("finetune", "synthetic -> fine-tune")):
        s = summary.get(arm, {})
        if not s:
            continue
        n = np.array(sorted(s))
        mean = np.array([s[k]["mean"] for k in n])
        lo, hi = np.array([s[k]["min"] for k in n]), np.array([s[k]["max"] for k in n])
        ax.plot(n, mean, marker="o", label=label)
        ax.fill_between(n, lo, hi, alpha=0.2)
    for i, (name, summ) in enumerate((cross or {}).items()):
        for arm, style in (("real", ":"), ("finetune", "--")):
            s = summ.get(arm, {})
            if s:
                n = np.array(sorted(s))
                ax.plot(n, [s[k]["mean"] for k in n], style, color=f"C{i + 2}", lw=1,
                        label=f"{name} ({'real only' if arm == 'real' else 'fine-tune'})")
    ax.set_xlabel("labelled real photos (N)")
    ax.set_ylabel("F1 at the validation threshold")
    ax.set_ylim(0, 1)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=6 if cross else 8)
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
