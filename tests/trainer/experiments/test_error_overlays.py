"""Error overlays and false-positive shapes on a hand-made photo with a known label and a known prediction."""
import cv2
import numpy as np

from trainer.experiments.error_overlays import component_shapes, describe_errors, error_overlay
from trainer.seg.sources import RealFolder


def test_false_positives_are_counted_and_described(tmp_path):
    (tmp_path / "images").mkdir()
    (tmp_path / "masks").mkdir()
    img = np.full((60, 80, 3), 160, np.uint8)
    img[10:13, 5:75] = 40   # a dark crack (labelled)
    img[40:43, 5:75] = 40   # a dark joint line (not labelled): a line-like, dark false positive
    img[25:31, 30:36] = 230  # a bright blob (not labelled)
    label = np.zeros((60, 80), np.uint8)
    label[10:13, 5:75] = 255
    cv2.imwrite(str(tmp_path / "images" / "a.png"), img)
    cv2.imwrite(str(tmp_path / "masks" / "a.png"), label)
    folder = RealFolder(tmp_path)

    def probability(s):  # calls dark pixels and the bright blob crack, misses the crack's last 10 px
        p = (s["rgb"][..., 0] < 100).astype(np.float32)
        p[25:31, 30:36] = 1.0
        p[10:13, 65:75] = 0.0
        return p

    r = describe_errors(folder, probability, 0.5, tmp_path / "out", worst=2)
    assert (r["tp"], r["fp"], r["fn"]) == (3 * 60, 3 * 70 + 36, 3 * 10)
    assert r["fp_components"] == 2 and r["images_with_fp"] == 1
    assert r["fp_line_like"] == (3 * 70) / (3 * 70 + 36)  # the joint line is line-like, the blob is not
    assert r["fp_darker_than_surround"] == (3 * 70) / (3 * 70 + 36)
    assert r["fp_brighter_than_surround"] == 36 / (3 * 70 + 36)
    over = cv2.imread(r["overlays"][0])[..., ::-1]
    assert over.shape == (60, 160, 3)
    right = over[:, 80:]
    assert right[41, 40, 0] > 150 and right[41, 40, 1] < 120  # false positive: red
    assert right[11, 40, 1] > 150 and right[11, 40, 0] < 120  # true positive: green
    assert right[11, 70, 2] > 150  # missed: blue
    assert np.array_equal(error_overlay(img, np.zeros((60, 80), bool), np.zeros((60, 80), bool)), img)


def test_component_shapes_on_a_line_and_a_square():
    m = np.zeros((50, 50), bool)
    m[5, 5:45] = True
    m[30:36, 30:36] = True
    grey = np.full((50, 50), 100.0)
    shapes = sorted(component_shapes(m, grey), key=lambda c: c["pixels"])
    assert shapes[0]["pixels"] == 36 and shapes[0]["elongation"] < 1.5
    assert shapes[1]["pixels"] == 40 and shapes[1]["elongation"] > 10
