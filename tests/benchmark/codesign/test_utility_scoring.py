"""Utility scores against the official cityscapesScripts evaluation."""

import math

import numpy as np
import pytest
import torch
from PIL import Image

from benchmark.codesign.utility.scoring import confusion_matrix, scores


def test_matches_cityscapes_scripts(tmp_path):
    import cityscapesscripts.evaluation.evalPixelLevelSemanticLabeling as cs
    from cityscapesscripts.helpers.labels import trainId2label

    rng = np.random.default_rng(0)
    truth = rng.integers(0, 19, (3, 40, 60)).astype(np.uint8)
    truth[:, :5] = 255  # ignored rows
    truth[truth == 16] = 3  # class 16 (train) absent from the ground truth
    pred = np.where(rng.random(truth.shape) < 0.6, truth, rng.integers(0, 19, truth.shape)).astype(np.uint8)
    pred[pred == 255] = 0
    pred[pred == 17] = 2  # class 17 never predicted

    to_label_id = np.zeros(256, dtype=np.uint8)
    for train_id, label in trainId2label.items():
        if 0 <= train_id < 19:
            to_label_id[train_id] = label.id
    args = cs.args
    args.evalInstLevelScore, args.quiet = False, True
    args.evalLabels = sorted({label.id for train_id, label in trainId2label.items() if 0 <= train_id < 19} | {0})
    matrix = cs.generateMatrix(args)
    for i in range(len(truth)):
        p, g = tmp_path / f"p{i}.png", tmp_path / f"g{i}.png"
        Image.fromarray(to_label_id[pred[i]]).save(p)
        Image.fromarray(to_label_id[truth[i]]).save(g)
        cs.evaluatePair(str(p), str(g), matrix, {}, {}, args)  # accumulates into matrix in place
    official = [cs.getIouScoreForLabel(trainId2label[t].id, matrix, args) for t in range(19)]

    ours = scores(confusion_matrix(torch.from_numpy(pred), torch.from_numpy(truth)))
    for t in range(19):
        if math.isnan(official[t]):
            assert math.isnan(ours["class_iou"][t])
        else:
            assert ours["class_iou"][t] == pytest.approx(official[t], abs=1e-12)
    assert ours["miou"] == pytest.approx(np.nanmean(official), abs=1e-12)


def test_accuracies_closed_form():
    truth = torch.tensor([[0, 0, 1, 1, 255]])
    pred = torch.tensor([[0, 1, 1, 1, 0]])
    s = scores(confusion_matrix(pred, truth, n_classes=2))
    assert s["overall_acc"] == pytest.approx(3 / 4)
    assert s["mean_acc"] == pytest.approx((1 / 2 + 1) / 2)
    assert s["miou"] == pytest.approx((1 / 2 + 2 / 3) / 2)
