"""Rectification against OpenCV: jem's maps and rectified views against cv2.stereoRectify (alpha 0, 0.5, 1) +
initUndistortRectifyMap + remap, on a rig made here (known cameras with lens distortion looking at a textured
scene), its calibration saved by cv2.FileStorage as YAML and XML, and as KITTI's calib_cam_to_cam.txt."""

import warnings

import numpy as np
import pytest

import jem

cv2 = pytest.importorskip("cv2")

SIZE = (640, 480)
K1 = np.array([[702.0, 0.0, 318.5], [0.0, 698.0, 243.0], [0.0, 0.0, 1.0]])
K2 = np.array([[690.0, 0.0, 326.0], [0.0, 693.5, 236.5], [0.0, 0.0, 1.0]])
D1 = np.array([[-0.21, 0.09, 0.0012, -0.0007, -0.015]])
D2 = np.array([[-0.18, 0.06, -0.0009, 0.0011, 0.01]])
R, _ = cv2.Rodrigues(np.array([[0.012], [-0.031], [0.0075]]))
T = np.array([[-0.12], [0.0035], [-0.0021]])


def save_calibration(path, size=SIZE):
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for name, value in (("K1", K1), ("D1", D1), ("K2", K2), ("D2", D2), ("R", R), ("T", T)):
        fs.write(name, value)
    fs.write("image_width", size[0])
    fs.write("image_height", size[1])
    fs.release()
    return path


def opencv_rectify(size=SIZE, alpha=0):
    return cv2.stereoRectify(K1, D1, K2, D2, size, R, T, flags=cv2.CALIB_ZERO_DISPARITY, alpha=alpha)


def opencv_maps(size=SIZE):
    R1, R2, P1, P2, Q, _, _ = opencv_rectify(size)
    left = cv2.initUndistortRectifyMap(K1, D1, R1, P1, size, cv2.CV_32FC1)
    right = cv2.initUndistortRectifyMap(K2, D2, R2, P2, size, cv2.CV_32FC1)
    return left, right, (R1, R2, P1, P2, Q)


def texture(u, v):
    """A smooth texture with fine detail on a plane (u, v in metres), 0..255."""
    t = 0.5 + 0.2 * np.sin(40 * u) * np.cos(33 * v) + 0.15 * np.sin(97 * u + 61 * v) + 0.1 * np.cos(151 * v - 23 * u)
    return np.clip(255 * t, 0, 255)


def render(K, D, rot, trans, size=SIZE):
    """The raw (distorted) view of a camera at X_cam = rot·X_left + trans of a slanted textured plane in the left
    camera's frame (Z = 2 + 0.3·X)."""
    w, h = size
    pix = np.stack(np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64)), -1).reshape(-1, 1, 2)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    rays = cv2.undistortPoints(pix, K, D, R=None, P=None, criteria=criteria).reshape(-1, 2)
    dirs = np.concatenate([rays, np.ones((len(rays), 1))], 1) @ rot  # in the left frame: rotᵀ·d
    origin = (-rot.T @ trans).ravel()
    # origin + s·dir on Z − 0.3·X = 2.
    s = (2.0 - origin[2] + 0.3 * origin[0]) / (dirs[:, 2] - 0.3 * dirs[:, 0])
    points = origin + s[:, None] * dirs
    grey = texture(points[:, 0], points[:, 1]).reshape(h, w)
    rgb = np.stack([grey, 0.8 * grey + 20, 255 - grey], -1)
    return np.round(rgb).astype(np.uint8)


@pytest.fixture(scope="module")
def raw_pair():
    return render(K1, D1, np.eye(3), np.zeros((3, 1))), render(K2, D2, R, T)


@pytest.mark.parametrize("ext", ["yml", "xml"])
def test_maps_and_transforms_match_opencv(tmp_path, ext):
    maps = jem.rectify_maps(save_calibration(tmp_path / f"stereo.{ext}"))
    (l1, l2), (r1, r2), (R1, R2, P1, P2, Q) = opencv_maps()
    for ours, theirs in ((maps["R1"], R1), (maps["R2"], R2)):
        np.testing.assert_allclose(np.array(ours), theirs, atol=1e-9)
    for ours, theirs in ((maps["P1"], P1), (maps["P2"], P2), (maps["Q"], Q)):
        np.testing.assert_allclose(np.array(ours), theirs, rtol=1e-6, atol=1e-6)
    worst = max(np.abs(maps[k] - m).max() for k, m in (("map1x", l1), ("map1y", l2), ("map2x", r1), ("map2y", r2)))
    print(f"largest map difference from OpenCV: {worst:.2e} px")
    assert worst <= 0.01
    assert maps["baseline"] == pytest.approx(float(np.linalg.norm(T)), rel=1e-9)


@pytest.mark.parametrize("alpha", [0, 0.5, 1])
def test_alpha_and_valid_rectangles_match_opencv(tmp_path, cli, raw_pair, alpha):
    calib = save_calibration(tmp_path / "stereo.yml")
    maps = jem.rectify_maps(calib, alpha=alpha)
    R1, R2, P1, P2, Q, roi1, roi2 = opencv_rectify(alpha=alpha)
    for ours, theirs in ((maps["R1"], R1), (maps["R2"], R2)):
        np.testing.assert_allclose(np.array(ours), theirs, atol=1e-9)
    for ours, theirs in ((maps["P1"], P1), (maps["P2"], P2), (maps["Q"], Q)):
        np.testing.assert_allclose(np.array(ours), theirs, rtol=1e-6, atol=1e-6)
    print(f"alpha {alpha}: ROI {maps['roi1']} {maps['roi2']}, OpenCV's {roi1} {roi2}")
    for ours, theirs in ((maps["roi1"], roi1), (maps["roi2"], roi2)):
        assert np.abs(np.subtract(ours, theirs)).max() <= 1, (ours, theirs)
    # The CLI writes the same rectification, which cv2.FileStorage reads: matrices and the valid rectangles.
    for name, view in zip(("left.png", "right.png"), raw_pair):
        cv2.imwrite(str(tmp_path / name), view[..., ::-1])
    cli("rectify", calib, tmp_path / "left.png", tmp_path / "right.png", "-o", tmp_path / "out", "--alpha", str(alpha))
    fs = cv2.FileStorage(str(tmp_path / "out" / "rectify.yml"), cv2.FILE_STORAGE_READ)
    for name, theirs in (("P1", P1), ("P2", P2), ("Q", Q), ("R1", R1), ("R2", R2)):
        np.testing.assert_allclose(fs.getNode(name).mat(), theirs, rtol=1e-6, atol=1e-6)
    for name, ours in (("validPixROI1", maps["roi1"]), ("validPixROI2", maps["roi2"])):
        node = fs.getNode(name)
        assert [int(node.at(i).real()) for i in range(node.size())] == list(ours)
    fs.release()


def test_alpha_is_refused_out_of_range(tmp_path):
    calib = save_calibration(tmp_path / "stereo.yml")
    with pytest.raises(ValueError, match=r"alpha"):
        jem.rectify_maps(calib, alpha=1.5)


def test_grey_views_stay_grey(tmp_path, raw_pair):
    calib = save_calibration(tmp_path / "stereo.yml")
    grey = [cv2.cvtColor(view, cv2.COLOR_RGB2GRAY) for view in raw_pair]
    left, right, _ = jem.rectify(calib, *grey)
    assert left.shape == right.shape == (SIZE[1], SIZE[0])
    # The grey rectified view is the colour rectification of the grey view, channel for channel.
    rgb_left, _, _ = jem.rectify(calib, np.dstack([grey[0]] * 3), np.dstack([grey[1]] * 3))
    assert rgb_left.shape == (SIZE[1], SIZE[0], 3)
    np.testing.assert_array_equal(left, rgb_left[..., 0])


def test_kitti_calibration_gives_opencvs_maps(tmp_path):
    # Camera 02 at the origin of camera 00's frame, 03 at (R, T) from it: KITTI's poses of both in camera 00's.
    line = lambda a: " ".join(f"{v:.12e}" for v in np.ravel(a))  # noqa: E731
    text = "calib_time: 09-Jan-2012 13:57:47\ncorner_dist: 9.950000e-02\n"
    for cam, (K, D, rot, trans) in (("02", (K1, D1, np.eye(3), np.zeros(3))), ("03", (K2, D2, R, T))):
        text += f"S_{cam}: {SIZE[0]} {SIZE[1]}\nK_{cam}: {line(K)}\nD_{cam}: {line(D)}\nR_{cam}: {line(rot)}\nT_{cam}: {line(trans)}\n"
    (tmp_path / "calib_cam_to_cam.txt").write_text(text)
    maps = jem.rectify_maps(tmp_path / "calib_cam_to_cam.txt")
    (l1, l2), (r1, r2), _ = opencv_maps()
    assert max(np.abs(maps["map1x"] - l1).max(), np.abs(maps["map2y"] - r2).max()) <= 0.01


def test_rectified_views_match_opencvs_remap(tmp_path, cli, raw_pair):
    calib = save_calibration(tmp_path / "stereo.yml")
    cv2.imwrite(str(tmp_path / "left.png"), raw_pair[0][..., ::-1])
    cv2.imwrite(str(tmp_path / "right.png"), raw_pair[1][..., ::-1])
    cli("rectify", calib, tmp_path / "left.png", tmp_path / "right.png", "-o", tmp_path / "out")
    (l1, l2), (r1, r2), (_, _, P1, P2, _) = opencv_maps()
    for name, raw, (mx, my) in (("im0.png", raw_pair[0], (l1, l2)), ("im1.png", raw_pair[1], (r1, r2))):
        theirs = cv2.remap(raw, mx, my, cv2.INTER_LINEAR)
        ours = jem.read_image(tmp_path / "out" / name)
        diff = np.abs(ours.astype(int) - theirs.astype(int))
        within = (diff <= 1).mean()
        print(f"{name}: {100 * within:.3f} % of samples within 1 grey level of OpenCV, largest {diff.max()}")
        assert within >= 0.999
    calib_txt = dict(line.split("=", 1) for line in (tmp_path / "out" / "calib.txt").read_text().splitlines())
    assert float(calib_txt["baseline"]) == pytest.approx(-P2[0, 3] / P2[0, 0], rel=1e-6)
    assert float(calib_txt["doffs"]) == pytest.approx(P2[0, 2] - P1[0, 2], abs=1e-6)
    assert (calib_txt["width"], calib_txt["height"]) == (str(SIZE[0]), str(SIZE[1]))
    # The Python module rectifies to the same bytes.
    left, right, text = jem.rectify(calib, *raw_pair)
    np.testing.assert_array_equal(left, jem.read_image(tmp_path / "out" / "im0.png"))
    np.testing.assert_array_equal(right, jem.read_image(tmp_path / "out" / "im1.png"))
    assert text == (tmp_path / "out" / "calib.txt").read_text()


def test_match_with_rectify_is_matching_the_rectified_pair(tmp_path, cli):
    size = (200, 150)
    scale = np.diag([size[0] / SIZE[0], size[1] / SIZE[1], 1.0])
    k1, k2 = scale @ K1, scale @ K2
    calib = tmp_path / "small.yml"
    fs = cv2.FileStorage(str(calib), cv2.FILE_STORAGE_WRITE)
    for name, value in (("M1", k1), ("D1", D1), ("M2", k2), ("D2", D2), ("R", R), ("T", T)):
        fs.write(name, value)
    fs.release()
    left, right = render(k1, D1, np.eye(3), np.zeros((3, 1)), size), render(k2, D2, R, T, size)
    cv2.imwrite(str(tmp_path / "left.png"), left[..., ::-1])
    cv2.imwrite(str(tmp_path / "right.png"), right[..., ::-1])
    cli("rectify", calib, tmp_path / "left.png", tmp_path / "right.png", "-o", tmp_path / "rect")
    cli(tmp_path / "rect" / "im0.png", tmp_path / "rect" / "im1.png", "-o", tmp_path / "two-steps.pfm", "--ndisp", "32")
    cli("match", tmp_path / "left.png", tmp_path / "right.png", "--rectify", calib, "-o", tmp_path / "one-step.pfm",
        "--ndisp", "32")
    assert (tmp_path / "one-step.pfm").read_bytes() == (tmp_path / "two-steps.pfm").read_bytes()
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        disp = jem.match(left, right, ndisp=32, rectify=calib, overrides={})
    np.testing.assert_array_equal(disp, jem.read_pfm(tmp_path / "one-step.pfm"))
    # A pair rectified with rectify= is never told to rectify it (as `jem match --rectify` words it).
    assert not [w for w in said if "--rectify CALIB" in str(w.message)], [str(w.message) for w in said]
    # Raw views given in the wrong order: rectified with the calibration, the pair still looks unrectified, and the
    # warning asks about the calibration and the order of the views.
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        jem.match(right, left, ndisp=32, rectify=calib, overrides={})
    messages = [str(w.message) for w in said]
    assert any("after --rectify" in m and "small.yml" in m for m in messages), messages
    assert not any("--rectify CALIB" in m for m in messages), messages


def test_a_calibration_missing_values_names_them_all(tmp_path):
    path = tmp_path / "partial.yml"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("K1", K1)
    fs.write("R", R)
    fs.release()
    with pytest.raises(ValueError, match=r"partial\.yml: missing D1/distCoeffs1, K2/M2/cameraMatrix2, D2/distCoeffs2, T"):
        jem.rectify_maps(path, size=SIZE)
