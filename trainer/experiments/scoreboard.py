"""The cross-domain scoreboard: several models on several labelled sets, in one table.

Pure parts of ``cracktrain benchmark``: each model is scored on each set at its own
validation threshold (never one chosen on the set), at 0.5, and at the set's own
best threshold (labelled an oracle). Models that share a label are seeds of one
configuration and are summarised as mean ± sample standard deviation (ddof 1).
A model is anything with ``histogram(folder) -> ConfusionHistogram``, so the table
logic is tested on hand-made models; ``trainer.experiments.benchmark`` wraps checkpoints.
"""
from __future__ import annotations

import csv
import math
import textwrap
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Iterable, Mapping, Protocol, Sequence

import numpy as np

from trainer.seg.metrics import ConfusionHistogram
from trainer.seg.scoring import report
from trainer.seg.sources import RealFolder

METRICS = ("precision", "recall", "f1", "iou", "f1_at_0.5", "oracle_f1")
HEADLINE = "f1"


class Scorer(Protocol):
    def histogram(self, folder: RealFolder) -> ConfusionHistogram: ...


@dataclass
class EvalSet:
    """A labelled real set scored by every model (``name`` heads its column)."""

    name: str
    folder: RealFolder
    description: str


@dataclass
class ModelEntry:
    """One trained model: ``label`` groups seeds of one configuration; ``threshold`` comes from validation."""

    label: str
    path: str
    threshold: float
    threshold_source: str
    scorer: Scorer


@dataclass
class ScoreRow:
    """One model on one set (a line of ``benchmark.csv``)."""

    label: str
    model: str
    set: str
    images: int
    threshold: float
    threshold_source: str
    precision: float
    recall: float
    f1: float
    iou: float
    f1_at_0_5: float
    oracle_f1: float
    oracle_threshold: float

    def metric(self, name: str) -> float:
        return {"f1_at_0.5": self.f1_at_0_5}.get(name, getattr(self, name, None))


def score_row(entry: ModelEntry, s: EvalSet, hist: ConfusionHistogram) -> ScoreRow:
    r = report(hist, entry.threshold)
    a, o = r["at_threshold"], r["oracle"]
    return ScoreRow(label=entry.label, model=entry.path, set=s.name, images=len(s.folder), threshold=a["threshold"],
                    threshold_source=entry.threshold_source, precision=a["precision"], recall=a["recall"],
                    f1=a["f1"], iou=a["iou"], f1_at_0_5=r["at_0.5"]["f1"], oracle_f1=o["f1"],
                    oracle_threshold=o["threshold"])


def score_all(entries: Sequence[ModelEntry], sets: Sequence[EvalSet],
              on_done: Callable[[ScoreRow], None] | None = None) -> list[ScoreRow]:
    """Every model on every set, in model order."""
    rows = []
    for e in entries:
        for s in sets:
            row = score_row(e, s, e.scorer.histogram(s.folder))
            rows.append(row)
            if on_done is not None:
                on_done(row)
    return rows


def mean_sd(values: Iterable[float]) -> tuple[float, float, int]:
    """(mean, sample standard deviation with ddof 1 (nan for one value), count)."""
    v = np.asarray(list(values), dtype=np.float64)
    sd = float(np.std(v, ddof=1)) if v.size > 1 else math.nan
    return float(v.mean()), sd, int(v.size)


def fmt(mean: float, sd: float) -> str:
    return f"{mean:.3f}" if math.isnan(sd) else f"{mean:.3f} ± {sd:.3f}"


def summarise(rows: Sequence[ScoreRow]) -> dict[str, dict[str, dict[str, tuple[float, float, int]]]]:
    """label -> set -> metric -> (mean, sd, n), labels and sets in first-seen order."""
    out: dict[str, dict[str, dict[str, tuple[float, float, int]]]] = {}
    for label in dict.fromkeys(r.label for r in rows):
        for name in dict.fromkeys(r.set for r in rows):
            mine = [r for r in rows if r.label == label and r.set == name]
            if mine:
                out.setdefault(label, {})[name] = {m: mean_sd(r.metric(m) for r in mine) for m in METRICS}
    return out


def markdown_lines(rows: Sequence[ScoreRow], sets: Sequence[EvalSet],
                   costs: Mapping[str, float] | None = None, renders: Mapping[str, int] | None = None) -> list[str]:
    """Headline table (F1 at the validation threshold, one column per set; with ``costs``, label -> core-seconds
    per training sample, a cost column; with ``renders``, label -> training renders, a renders column) and the
    full table."""
    summ = summarise(rows)
    names = [s.name for s in sets]
    n_models = {label: sum(r.label == label and r.set == next(iter(by_set)) for r in rows)
                for label, by_set in summ.items()}
    extra = [(head, values, form) for head, values, form in
             (("renders", renders, "{:d}"), ("core-s / sample", costs, "{:.2f}")) if values]
    lines = ["F1 at each model's validation threshold (mean ± sample sd over the models of a row):", "",
             "| model | n | " + "".join(f"{head} | " for head, _, _ in extra) + " | ".join(names) + " |",
             "|---|---|" + "---|" * len(extra) + "---|" * len(names)]
    for label, by_set in summ.items():
        cells = [fmt(*by_set[n][HEADLINE][:2]) if n in by_set else "–" for n in names]
        known = "".join((form.format(values[label]) if label in values else "–") + " | " for _, values, form in extra)
        lines.append(f"| {label} | {n_models[label]} | {known}" + " | ".join(cells) + " |")
    lines += ["", "All figures (P, R, F1 and IoU at the validation threshold; F1 at 0.5; oracle F1 at the set's "
              "own best threshold, which looks at the labels being scored):", "",
              "| model | set | precision | recall | **F1** | IoU | F1 @ 0.5 | oracle F1 |", "|---|---|---|---|---|---|---|---|"]
    for label, by_set in summ.items():
        for n in names:
            if n in by_set:
                m = by_set[n]
                cells = [fmt(*m[k][:2]) for k in ("precision", "recall")] + [f"**{fmt(*m['f1'][:2])}**"] + \
                        [fmt(*m[k][:2]) for k in ("iou", "f1_at_0.5", "oracle_f1")]
                lines.append(f"| {label} | {n} | " + " | ".join(cells) + " |")
    lines += ["", "Sets:", ""] + [f"- `{s.name}`: {s.description} ({len(s.folder)} images)" for s in sets]
    thresholds = {(r.model, r.threshold, r.threshold_source) for r in rows}
    lines += ["", "Models and their thresholds:", ""] + [f"- `{m}`: {t:.2f} ({src})" for m, t, src in sorted(thresholds)]
    return lines


def write_csv(rows: Sequence[ScoreRow], path: Path) -> None:
    fields = list(ScoreRow.__dataclass_fields__)
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        for r in rows:
            w.writerow(asdict(r))


def plot_bars(rows: Sequence[ScoreRow], sets: Sequence[EvalSet], path: Path, title: str) -> None:
    """Grouped bars: one group per set, one bar per label (mean F1 at the validation threshold, sd as error bar)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    summ = summarise(rows)
    names = [s.name for s in sets]
    labels = list(summ)
    width = 0.8 / max(1, len(labels))
    x = np.arange(len(names))
    fig, ax = plt.subplots(figsize=(max(6, 1.6 * len(names) + 0.4 * len(labels)), 4), dpi=120)
    for i, label in enumerate(labels):
        mean = [summ[label].get(n, {}).get(HEADLINE, (math.nan, math.nan, 0))[0] for n in names]
        sd = [summ[label].get(n, {}).get(HEADLINE, (math.nan, math.nan, 0))[1] for n in names]
        ax.bar(x + (i - (len(labels) - 1) / 2) * width, mean, width,
               yerr=[0 if math.isnan(s) else s for s in sd], capsize=2, label=label)
    ax.set_xticks(x, names, fontsize=8)
    ax.set_ylabel("F1 at the validation threshold")
    ax.set_ylim(0, 1)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    ax.set_title(textwrap.fill(title, 100), fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_cost(rows: Sequence[ScoreRow], sets: Sequence[EvalSet], costs: Mapping[str, float], path: Path,
              title: str) -> None:
    """F1 (mean ± sd over a row's models) against the core-seconds one training sample of the row cost: one line
    per set through the rows that have a cost, each point named by its row."""
    plot_against(rows, sets, costs, path, title, "core-seconds per training sample (crackgen bench)")


def plot_volume(rows: Sequence[ScoreRow], sets: Sequence[EvalSet], renders: Mapping[str, int], path: Path,
                title: str) -> None:
    """F1 against the number of training renders (log2 axis: the data-volume curve), one line per set."""
    plot_against(rows, sets, renders, path, title, "training renders (log scale)", log2=True)


def plot_against(rows: Sequence[ScoreRow], sets: Sequence[EvalSet], xs: Mapping[str, float], path: Path,
                 title: str, xlabel: str, log2: bool = False) -> None:
    """F1 (mean ± sd over a row's models) against one number per row: a line per set through the rows that have
    one, each point named by its row."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    summ = summarise(rows)
    labels = sorted((label for label in summ if label in xs), key=lambda label: xs[label])
    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=120)
    for s in sets:
        pts = [(xs[label], *summ[label][s.name][HEADLINE][:2]) for label in labels if s.name in summ[label]]
        if not pts:
            continue
        x, mean, sd = (np.asarray(v, dtype=np.float64) for v in zip(*pts))
        ax.errorbar(x, mean, yerr=np.nan_to_num(sd), marker="o", capsize=3, label=s.name)
    top = max((summ[label][n][HEADLINE][0] for label in labels for n in summ[label]), default=1.0)
    for label in labels:
        ax.annotate(label, (xs[label], top), textcoords="offset points", xytext=(0, 8), ha="center", fontsize=7,
                    rotation=30)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("F1 at the validation threshold")
    ax.set_ylim(0, 1)
    if log2:
        ax.set_xscale("log", base=2)
        ax.set_xticks(sorted(set(xs[label] for label in labels)))
        from matplotlib.ticker import ScalarFormatter

        ax.get_xaxis().set_major_formatter(ScalarFormatter())
    else:
        ax.set_xlim(left=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title(textwrap.fill(title, 100), fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
