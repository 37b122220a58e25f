"""Utility scores from one confusion matrix over a whole split (Cityscapes conventions).

mIoU = mean over classes of TP / (TP + FP + FN); mean accuracy (mA) = mean over classes of
TP / (TP + FN); overall accuracy (OA) = correct pixels / labelled pixels. Pixels labelled 255 are
ignored; a class absent from both the ground truth and the predictions is left out of the means
(NaN), as cityscapesScripts does.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from benchmark.codesign.utility.segformer import sliding_window_logits

N_CLASSES = 19
IGNORE = 255


def confusion_matrix(pred: torch.Tensor, target: torch.Tensor, n_classes: int = N_CLASSES) -> torch.Tensor:
    """(n, n) int64 counts, rows = ground truth, columns = prediction; target 255 ignored."""
    keep = target != IGNORE
    idx = target[keep].long() * n_classes + pred[keep].long()
    return torch.bincount(idx, minlength=n_classes * n_classes).reshape(n_classes, n_classes)


def scores(conf: torch.Tensor) -> dict[str, object]:
    """miou, mean_acc, overall_acc (floats in [0,1]) and per-class IoU (list, NaN where undefined)."""
    c = conf.double()
    tp = c.diag()
    gt, predicted = c.sum(1), c.sum(0)
    with np.errstate(invalid="ignore", divide="ignore"):
        iou = (tp / (gt + predicted - tp)).numpy()
        acc = (tp / gt).numpy()
    return {"miou": float(np.nanmean(iou)), "mean_acc": float(np.nanmean(acc)),
            "overall_acc": float(tp.sum() / c.sum()), "class_iou": [float(v) for v in iou]}


def window_for(image_size: tuple[int, int], crop: tuple[int, int]) -> tuple[tuple[int, int], tuple[int, int]]:
    """Sliding window (twice the training crop, at most the image) and stride (3/4 window)."""
    win = (min(2 * crop[0], image_size[0]), min(2 * crop[1], image_size[1]))
    return win, (max(1, win[0] * 3 // 4), max(1, win[1] * 3 // 4))


@torch.no_grad()
def predict(net: torch.nn.Module, images: torch.Tensor, window: tuple[int, int], stride: tuple[int, int],
            batch_size: int = 4, device: str = "cpu",
            logits: Callable[[torch.Tensor], torch.Tensor] | None = None) -> torch.Tensor:
    """Train-id predictions (N, H, W) uint8 by sliding-window inference at full resolution.

    ``batch_size`` images go through each window position together; ``logits`` computes a batch of
    windows' full-size logits (default: ``net`` with torch; see ``sliding_window_logits``).
    """
    net.eval()
    out = []
    for start in range(0, images.shape[0], batch_size):
        averaged = sliding_window_logits(net, images[start:start + batch_size].to(device), window=window,
                                         stride=stride, logits=logits)
        out.append(averaged.argmax(1).to(torch.uint8).cpu())
    return torch.cat(out)
