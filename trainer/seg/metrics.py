"""Dataset-level segmentation metrics and the PR curve (thesis 5.4.1).

Why a histogram: the thesis sums TP/FP/TN/FN over the whole test set at 101
thresholds 0.00, 0.01, ..., 1.00. Instead of 101 passes we bucket every
probability once per class (crack / background): a pixel is predicted crack at
threshold t_k = k/100 iff p >= t_k, so TP(t_k) is the number of crack pixels
in buckets >= k (a reverse cumulative sum). Bucket k holds p in [t_k, t_k+1).

Undefined ratios (0/0, e.g. precision with no positive prediction) are 0.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

N_THRESHOLDS = 101
THRESHOLDS = (torch.arange(N_THRESHOLDS, dtype=torch.float64) / 100).float()


def _div(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return np.divide(a, b, out=np.zeros(np.broadcast(a, b).shape), where=b > 0)


def scores(tp, fp, tn, fn) -> dict[str, np.ndarray | float]:
    """Accuracy, precision, recall, F1 and IoU from confusion counts (scalars or arrays)."""
    tp, fp, tn, fn = (np.asarray(x, dtype=np.float64) for x in (tp, fp, tn, fn))
    out = {
        "accuracy": _div(tp + tn, tp + fp + tn + fn),
        "precision": _div(tp, tp + fp),
        "recall": _div(tp, tp + fn),
        "f1": _div(2 * tp, 2 * tp + fp + fn),
        "iou": _div(tp, tp + fp + fn),
    }
    return {k: (float(v) if v.ndim == 0 else v) for k, v in out.items()}


@dataclass
class ConfusionHistogram:
    """Per-class probability histograms; all 101 confusion matrices at once."""

    pos: torch.Tensor  # [101] int64, crack pixels per bucket
    neg: torch.Tensor  # [101] int64, background pixels per bucket

    @classmethod
    def empty(cls) -> "ConfusionHistogram":
        return cls(torch.zeros(N_THRESHOLDS, dtype=torch.int64), torch.zeros(N_THRESHOLDS, dtype=torch.int64))

    def update(self, prob: torch.Tensor, target: torch.Tensor, ignore: torch.Tensor | None = None) -> None:
        """Add probabilities in [0,1] with binary targets (same shape; optional ignore mask)."""
        p = prob.detach().float().reshape(-1)
        t = target.detach().reshape(-1) > 0.5
        if ignore is not None:
            keep = ~ignore.reshape(-1).bool()
            p, t = p[keep], t[keep]
        thr = THRESHOLDS.to(p.device)
        bucket = (torch.bucketize(p.clamp(0.0, 1.0), thr, right=True) - 1).clamp_(0, N_THRESHOLDS - 1)
        self.pos += torch.bincount(bucket[t], minlength=N_THRESHOLDS).cpu()
        self.neg += torch.bincount(bucket[~t], minlength=N_THRESHOLDS).cpu()

    def merge(self, other: "ConfusionHistogram") -> None:
        self.pos += other.pos
        self.neg += other.neg

    def all_reduce(self) -> None:
        """Sum over DDP ranks (no-op without a process group)."""
        import torch.distributed as dist

        if dist.is_available() and dist.is_initialized():
            backend = dist.get_backend()
            dev = torch.device("cuda", torch.cuda.current_device()) if backend == "nccl" else torch.device("cpu")
            both = torch.stack([self.pos, self.neg]).to(dev)
            dist.all_reduce(both)
            self.pos, self.neg = both[0].cpu(), both[1].cpu()

    def confusion(self) -> dict[str, np.ndarray]:
        """TP, FP, TN, FN arrays over the 101 thresholds."""
        pos, neg = self.pos.numpy().astype(np.int64), self.neg.numpy().astype(np.int64)
        tp = np.cumsum(pos[::-1])[::-1]
        fp = np.cumsum(neg[::-1])[::-1]
        return {"tp": tp, "fp": fp, "fn": pos.sum() - tp, "tn": neg.sum() - fp}

    def at(self, threshold: float) -> dict[str, float]:
        """Counts and scores at one of the 101 thresholds (nearest grid point)."""
        k = int(round(threshold * 100))
        if not 0 <= k < N_THRESHOLDS:
            raise ValueError(f"threshold must be in [0, 1], got {threshold}")
        c = {n: int(v[k]) for n, v in self.confusion().items()}
        return {"threshold": k / 100, **c, **scores(c["tp"], c["fp"], c["tn"], c["fn"])}

    def pr_curve(self) -> dict[str, np.ndarray]:
        c = self.confusion()
        s = scores(c["tp"], c["fp"], c["tn"], c["fn"])
        return {"threshold": THRESHOLDS.double().numpy(), **c, **s}

    def best(self) -> dict[str, float]:
        """Scores at the best-F1 threshold (lowest threshold on ties)."""
        f1 = self.pr_curve()["f1"]
        return self.at(int(np.argmax(f1)) / 100)

    def summary(self, threshold: float = 0.5) -> dict:
        curve = self.pr_curve()
        return {
            "at_threshold": self.at(threshold),
            "best": self.best(),
            "pixels": {"crack": int(self.pos.sum()), "background": int(self.neg.sum())},
            "pr_curve": {k: [float(x) for x in curve[k]] for k in ("threshold", "precision", "recall", "f1", "iou")},
        }


def plot_pr_curve(hist: ConfusionHistogram, path: str | Path, title: str = "PR curve") -> None:
    """Write the precision-recall curve with the best-F1 point marked (matplotlib Agg)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    curve, best = hist.pr_curve(), hist.best()
    fig, ax = plt.subplots(figsize=(5, 5), dpi=100)
    ax.plot(curve["recall"], curve["precision"], "-", lw=1.5, label="PR (t = 0.00..1.00)")
    ax.plot([best["recall"]], [best["precision"]], "o", color="C3",
            label=f"best F1 {best['f1']:.3f} @ t={best['threshold']:.2f}")
    ax.set(xlabel="recall", ylabel="precision", xlim=(0, 1.02), ylim=(0, 1.02), title=title)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower left")
    fig.tight_layout()
    fig.savefig(str(path))
    plt.close(fig)
