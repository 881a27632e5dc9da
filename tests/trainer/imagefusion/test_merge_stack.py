"""`cracktrain merge-stack`: writes the fused image, prints the four scores, one-line errors."""
import cv2
import numpy as np

from trainer.cli import main


def _pair(tmp_path):
    rng = np.random.default_rng(0)
    img = (255 * cv2.GaussianBlur(rng.random((48, 64, 3)), (0, 0), 1.2)).astype(np.uint8)
    blur = cv2.GaussianBlur(img, (0, 0), 3)
    a, b = img.copy(), img.copy()
    a[:, 32:] = blur[:, 32:]
    b[:, :32] = blur[:, :32]
    pa, pb = tmp_path / "a.png", tmp_path / "b.png"
    cv2.imwrite(str(pa), a)
    cv2.imwrite(str(pb), b)
    return pa, pb


def test_fuse_images_writes_and_scores(tmp_path, capsys):
    pa, pb = _pair(tmp_path)
    out = tmp_path / "f" / "fused.png"
    assert main(["merge-stack", str(pa), str(pb), "--out", str(out), "--levels", "2"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0].startswith("Q_Y ") and "Q_MI" in lines[0] and str(out) in lines[-1]
    fused = cv2.imread(str(out))
    assert fused.shape == (48, 64, 3) and fused.dtype == np.uint8


def test_fuse_images_bad_inputs(tmp_path, capsys):
    pa, _ = _pair(tmp_path)
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.zeros((10, 10, 3), np.uint8))
    for argv, needle in (([str(pa), str(tmp_path / "missing.png")], "does not exist"),
                         ([str(pa), str(small)], "sizes must match"),
                         ([str(pa)], "at least 2")):
        rc = main(["merge-stack", *argv, "--out", str(tmp_path / "x.png")])
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 1 and len(err) == 1 and needle in err[0], (argv, err)
