import json
import struct
import sys
import zlib

import numpy as np
import pytest
from PIL import Image

from sppl.data.camera import CV_TO_GL, Camera, look_at
from sppl.data.observations import (
    CameraSpec,
    Frame,
    load_cameras,
    load_observations,
    write_observations,
)
from sppl.errors import ObservationError

W, H = 8, 6
POSE = look_at([3.0, -2.0, 1.5], [0.0, 0.0, 0.5])


def camera(name="cam0", **kw):
    args = dict(width=W, height=H, fx=9.0, fy=9.5, cx=4.25, cy=2.75, c2w=POSE, depth_max=5.0)
    return Camera(name=name, **{**args, **kw})


def random_frame(name="cam0", rng=None, **kw):
    rng = rng or np.random.default_rng(0)
    depth = rng.uniform(0.5, 4.5, (H, W)).astype(np.float32)
    depth[0, 0] = np.nan
    rgb = rng.uniform(0, 1, (H, W, 3)).astype(np.float32)
    return Frame(camera(name, **kw), rgb, depth, np.isfinite(depth))


def write_folder(tmp_path, transforms, images=(), depths=()):
    """An observation folder from a transforms dict, 8-bit images and .npy depth maps."""
    for rel, rgb in dict(images).items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(rgb).save(tmp_path / rel)
    for rel, depth in dict(depths).items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        np.save(tmp_path / rel, depth)
    (tmp_path / "transforms.json").write_text(json.dumps(transforms))
    return tmp_path


def simple_folder(tmp_path, frame_extra=(), top_extra=()):
    """One frame with an image and a depth map; a None in the extras removes that key."""
    rgb = np.full((H, W, 3), 128, np.uint8)
    depth = np.full((H, W), 2.0, np.float32)
    frame = {"file_path": "images/a.png", "depth_file_path": "depth/a.npy",
             "transform_matrix": POSE.tolist(), **dict(frame_extra)}  # fmt: skip
    transforms = {"fl_x": 9.0, "w": W, "h": H, **dict(top_extra)}
    frame = {k: v for k, v in frame.items() if v is not None}
    transforms = {k: v for k, v in transforms.items() if v is not None} | {"frames": [frame]}
    return write_folder(tmp_path, transforms, {"images/a.png": rgb}, {"depth/a.npy": depth})


def assert_same_camera(a: Camera, b: Camera):
    keys = ("name", "width", "height", "fx", "fy", "cx", "cy", "depth_max", "depth_type", "near")
    for key in keys:
        assert getattr(a, key) == getattr(b, key), key
    np.testing.assert_array_equal(a.c2w, b.c2w)


def png16_rgb(path, values):
    """A 16-bit RGB PNG written by hand: Pillow cannot write 16-bit colour."""
    h, w, _ = values.shape
    rows = values.astype(">u2")
    # Filter type 1 (Sub) on every row, so the decoder's filter handling is exercised.
    raw = b""
    for row in rows:
        b = np.frombuffer(row.tobytes(), np.uint8).astype(np.int16)
        sub = (b - np.concatenate([np.zeros(6, np.int16), b[:-6]])) % 256
        raw += b"\x01" + sub.astype(np.uint8).tobytes()

    def chunk(kind, data):
        crc = struct.pack(">I", zlib.crc32(kind + data))
        return struct.pack(">I", len(data)) + kind + data + crc

    header = struct.pack(">IIBBBBB", w, h, 16, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header)
                     + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))  # fmt: skip


# ---------------------------------------------------------------------------------------------
# Round trips


@pytest.mark.parametrize("depth_format", ["npy", "png"])
def test_round_trip(tmp_path, depth_format):
    frames = [
        random_frame("cam0"),
        Frame(camera("cam1", depth_type="ray", near=0.05), None, random_frame().depth, None),
        Frame(camera("cam/2"), random_frame().rgb),
    ]
    out = write_observations(tmp_path / "obs", frames, depth_format=depth_format)
    assert (out / f"depth/cam0.{depth_format}").is_file()
    obs = load_observations(out)
    assert [f.modalities for f in obs.frames] == [("rgb", "depth"), ("depth",), ("rgb",)]
    for wrote, read in zip(frames, obs.frames):
        assert_same_camera(wrote.camera, read.camera)
        if wrote.rgb is not None:
            assert read.rgb.dtype == np.float32 and read.rgb.shape == (H, W, 3)
            assert np.abs(read.rgb - wrote.rgb).max() <= 0.5 / 255 + 1e-6
        if wrote.depth is not None:
            assert read.depth.dtype == np.float32
            np.testing.assert_array_equal(read.depth_valid, np.isfinite(wrote.depth))
            if depth_format == "npy":
                np.testing.assert_array_equal(read.depth, wrote.depth)
            else:
                np.testing.assert_allclose(read.depth, wrote.depth, atol=0.5e-3, rtol=0)
    again = write_observations(tmp_path / "again", obs, depth_format=depth_format)
    again = load_observations(again)
    np.testing.assert_array_equal(again.frames[0].depth, obs.frames[0].depth)
    specs = load_cameras(out / "transforms.json")
    assert [s.modalities for s in specs] == [("rgb", "depth"), ("depth",), ("rgb",)]
    assert_same_camera(specs[1].camera, frames[1].camera)


def test_write_clips_and_rounds_rgb(tmp_path):
    frame = random_frame()
    frame.rgb[0, 0] = [-0.5, 1.5, 0.5]
    obs = load_observations(write_observations(tmp_path, [frame]))
    np.testing.assert_allclose(obs.frames[0].rgb[0, 0], [0.0, 1.0, 128 / 255])


def test_write_rejects_frames_without_data_and_depth_beyond_png_range(tmp_path):
    with pytest.raises(ObservationError, match="neither rgb nor depth"):
        write_observations(tmp_path, [Frame(camera())])
    frame = random_frame(depth_max=100.0)
    frame.depth[1, 1] = 70.0
    with pytest.raises(ObservationError, match="16-bit"):
        write_observations(tmp_path, [frame], depth_format="png")


def test_rgb_jpeg(tmp_path):
    rgb = np.full((H, W, 3), [200, 30, 90], np.uint8)
    frame = {"file_path": "a.jpg", "transform_matrix": POSE.tolist()}
    transforms = {"fl_x": 9.0, "frames": [frame]}
    frame = load_observations(write_folder(tmp_path, transforms, {"a.jpg": rgb})).frames[0]
    np.testing.assert_allclose(frame.rgb, rgb / 255, atol=4 / 255)


def test_rgb_8bit_rgba_and_16bit(tmp_path):
    rgba = np.zeros((H, W, 4), np.uint8)
    rgba[..., 0], rgba[..., 3] = 255, 7
    values = np.arange(H * W * 3).reshape(H, W, 3) * 401 % 65536
    png16_rgb(tmp_path / "b.png", values)
    transforms = {"fl_x": 9.0, "w": W, "h": H, "frames": [
        {"file_path": "a.png", "transform_matrix": POSE.tolist()},
        {"file_path": "b.png", "transform_matrix": POSE.tolist()}]}  # fmt: skip
    obs = load_observations(write_folder(tmp_path, transforms, {"a.png": rgba}))
    np.testing.assert_array_equal(obs.frames[0].rgb[..., 0], 1.0)
    assert obs.frames[0].rgb.shape == (H, W, 3)
    np.testing.assert_allclose(obs.frames[1].rgb, values / 65535, atol=1e-6)


# ---------------------------------------------------------------------------------------------
# Reading conventions


def test_camera_angle_x_fallback(tmp_path):
    angle = 0.6911112070083618
    simple_folder(tmp_path, top_extra={"fl_x": None, "camera_angle_x": angle})
    cam = load_observations(tmp_path).frames[0].camera
    assert cam.fx == pytest.approx(0.5 * W / np.tan(0.5 * angle))
    assert cam.fy == cam.fx
    assert (cam.cx, cam.cy) == (W / 2, H / 2)


def test_width_and_height_default_to_the_image_size(tmp_path):
    simple_folder(tmp_path, top_extra={"w": None, "h": None})
    cam = load_observations(tmp_path).frames[0].camera
    assert (cam.width, cam.height) == (W, H)


def test_per_frame_intrinsics_win_over_top_level(tmp_path):
    simple_folder(tmp_path, frame_extra={"fl_x": 20.0, "cy": 3.5, "depth_max": 2.5},
                  top_extra={"fl_y": 11.0, "cx": 4.5, "cy": 1.0, "depth_max": 8.0})  # fmt: skip
    cam = load_observations(tmp_path).frames[0].camera
    assert (cam.fx, cam.fy, cam.cx, cam.cy, cam.depth_max) == (20.0, 11.0, 4.5, 3.5, 2.5)


def test_frame_field_of_view_beats_top_level_focal(tmp_path):
    simple_folder(tmp_path, frame_extra={"camera_angle_x": 1.0})
    cam = load_observations(tmp_path).frames[0].camera
    assert cam.fx == pytest.approx(0.5 * W / np.tan(0.5))


def test_opencv_convention_is_converted(tmp_path):
    # An OpenCV camera at (1, 2, 3) looking along world +x, image "down" being world -z.
    cv = np.array([[0, 0, 1, 1], [-1, 0, 0, 2], [0, -1, 0, 3], [0, 0, 0, 1]], dtype=float)
    simple_folder(tmp_path, frame_extra={"transform_matrix": cv.tolist()},
                  top_extra={"camera_convention": "opencv"})  # fmt: skip
    c2w = load_observations(tmp_path).frames[0].camera.c2w
    expected = np.array([[0, 0, -1, 1], [-1, 0, 0, 2], [0, 1, 0, 3], [0, 0, 0, 1]], dtype=float)
    np.testing.assert_array_equal(c2w, expected)
    np.testing.assert_array_equal(c2w, cv @ CV_TO_GL)
    # OpenGL cameras look along their -z axis: world +x, as the OpenCV camera did.
    np.testing.assert_array_equal(-c2w[:3, 2], [1, 0, 0])


def test_millimetre_png_depth_with_integer_depth_scale(tmp_path):
    mm = np.full((H, W), 1500, np.uint16)
    mm[2, 3] = 0
    (tmp_path / "d").mkdir()
    Image.fromarray(mm).save(tmp_path / "d/a.png")
    transforms = {"fl_x": 9.0, "w": W, "h": H, "frames": [
        {"depth_file_path": "d/a.png", "transform_matrix": POSE.tolist()},
        {"depth_path": "d/a.png", "integer_depth_scale": 0.0002,
         "transform_matrix": POSE.tolist()}]}  # fmt: skip
    obs = load_observations(write_folder(tmp_path, transforms))
    assert obs.frames[0].rgb is None and obs.frames[0].name == "a"
    assert obs.frames[1].name == "a_1"  # default names are made unique
    assert np.nanmax(obs.frames[0].depth) == pytest.approx(1.5)
    assert np.nanmax(obs.frames[1].depth) == pytest.approx(0.3)
    assert not obs.frames[0].depth_valid[2, 3] and np.isnan(obs.frames[0].depth[2, 3])


def test_missing_depth_is_masked_and_far_depth_clipped(tmp_path):
    depth = np.full((H, W), 2.0, np.float32)
    depth[0, :4] = [0.0, np.nan, np.inf, -1.0]
    depth[1, 1] = 50.0
    transforms = {"fl_x": 9.0, "w": W, "h": H, "depth_max": 4.0, "frames": [
        {"depth_file_path": "a.npy", "transform_matrix": POSE.tolist()}]}  # fmt: skip
    frame = load_observations(write_folder(tmp_path, transforms, depths={"a.npy": depth})).frames[0]
    assert frame.depth_valid.sum() == H * W - 4
    assert not frame.depth_valid[0, :4].any()
    assert np.isnan(frame.depth[0, :4]).all()
    assert frame.depth[1, 1] == 4.0 and frame.depth_valid[1, 1]
    assert frame.camera.depth_max == 4.0


def test_exr_depth(tmp_path):
    openexr = pytest.importorskip("OpenEXR")
    depth = np.full((H, W), 1.25, np.float32)
    header = {"compression": openexr.ZIP_COMPRESSION, "type": openexr.scanlineimage}
    openexr.File(header, {"Z": depth}).write(str(tmp_path / "a.exr"))
    transforms = {"fl_x": 9.0, "w": W, "h": H, "frames": [
        {"depth_file_path": "a.exr", "transform_matrix": POSE.tolist()}]}  # fmt: skip
    frame = load_observations(write_folder(tmp_path, transforms)).frames[0]
    np.testing.assert_array_equal(frame.depth, depth)


def test_exr_without_openexr_says_what_to_install(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "OpenEXR", None)  # makes `import OpenEXR` fail
    (tmp_path / "a.exr").write_bytes(b"not really")
    transforms = {"fl_x": 9.0, "w": W, "h": H, "frames": [
        {"depth_file_path": "a.exr", "transform_matrix": POSE.tolist()}]}  # fmt: skip
    with pytest.raises(ObservationError, match="pip install openexr") as e:
        load_observations(write_folder(tmp_path, transforms))
    assert "a.exr" in str(e.value)


def test_nerf_synthetic_paths_without_extension(tmp_path):
    rgb = np.zeros((H, W, 4), np.uint8)
    transforms = {"camera_angle_x": 0.7, "frames": [
        {"file_path": "./train/r_0", "transform_matrix": POSE.tolist()}]}  # fmt: skip
    obs = load_observations(write_folder(tmp_path, transforms, {"train/r_0.png": rgb}))
    assert obs.frames[0].name == "r_0" and obs.frames[0].rgb_path.name == "r_0.png"


# ---------------------------------------------------------------------------------------------
# Cameras files


def test_load_cameras_with_look_at_and_modalities(tmp_path):
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps({"fl_x": 9.0, "w": W, "h": H, "frames": [
        {"name": "left", "look_at": {"eye": [3, -2, 1.5], "target": [0, 0, 0.5]},
         "modalities": ["depth"]},
        {"transform_matrix": POSE.tolist(), "depth_type": "ray"}]}))  # fmt: skip
    specs = load_cameras(path)
    assert all(isinstance(s, CameraSpec) for s in specs)
    assert [s.modalities for s in specs] == [("depth",), ("rgb", "depth")]
    assert [s.camera.name for s in specs] == ["left", "frame1"]
    np.testing.assert_allclose(specs[0].camera.c2w, POSE)
    assert specs[1].camera.depth_type == "ray"


@pytest.mark.parametrize(
    "frame, message",
    [
        ({"transform_matrix": POSE.tolist(), "modalities": ["rgb", "normals"]}, "'modalities'"),
        ({"look_at": {"eye": [0, 0, 3], "target": [0, 0, 0]}}, "parallel"),
        ({"look_at": {"eye": [1, 1, 1], "target": [1, 1, 1]}}, "same point"),
        ({"look_at": {"eye": [1, 1]}}, "'look_at'"),
        ({}, "missing 'transform_matrix'"),
    ],
)
def test_load_cameras_errors(tmp_path, frame, message):
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps({"fl_x": 9.0, "w": W, "h": H, "frames": [frame]}))
    with pytest.raises(ObservationError, match=message) as e:
        load_cameras(path)
    assert "cameras.json" in str(e.value) and "frames[0]" in str(e.value)


def test_load_cameras_needs_the_image_size(tmp_path):
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps({"fl_x": 9.0, "frames": [{"transform_matrix": POSE.tolist()}]}))
    with pytest.raises(ObservationError, match="missing 'w'"):
        load_cameras(path)


# ---------------------------------------------------------------------------------------------
# Validation: each error is one line naming the file


def error_of(call, *args) -> str:
    with pytest.raises(ObservationError) as e:
        call(*args)
    message = str(e.value)
    assert "\n" not in message
    return message


def test_folder_missing(tmp_path):
    assert "nope" in error_of(load_observations, tmp_path / "nope")


def test_transforms_missing(tmp_path):
    message = error_of(load_observations, tmp_path)
    assert str(tmp_path) in message and "transforms.json" in message


def test_transforms_not_json(tmp_path):
    (tmp_path / "transforms.json").write_text('{\n  "frames": [\n    {"file_path": }\n')
    message = error_of(load_observations, tmp_path)
    assert "transforms.json:3:19:" in message and "not valid JSON" in message


@pytest.mark.parametrize(
    "transforms, message",
    [([1, 2], "JSON object"), ({"fl_x": 1}, "missing key 'frames'"), ({"frames": []}, "empty")],
)
def test_transforms_structure(tmp_path, transforms, message):
    (tmp_path / "transforms.json").write_text(json.dumps(transforms))
    assert message in error_of(load_observations, tmp_path)


@pytest.mark.parametrize(
    "frame, top, message",
    [
        ({"file_path": None, "depth_file_path": None}, {}, "neither an image nor a depth map"),
        ({"file_path": "images/missing.png"}, {}, "'images/missing.png' not found"),
        ({"depth_file_path": "depth/missing.npy"}, {}, "'depth/missing.npy' not found"),
        ({"transform_matrix": None}, {}, "missing 'transform_matrix'"),
        ({"transform_matrix": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}, {}, "must be 4x4"),
        ({"transform_matrix": [[1, 0], [0]]}, {}, "4x4 list of numbers"),
        ({"transform_matrix": (np.eye(4) * [1, 1, np.nan, 1]).tolist()}, {}, "NaN or inf"),
        ({"transform_matrix": np.diag([2.0, 2, 2, 1]).tolist()}, {}, "not orthonormal"),
        ({"transform_matrix": np.diag([1.0, 1, -1, 1]).tolist()}, {}, "determinant -1"),
        ({"transform_matrix": (np.eye(4) + np.eye(4)[[3]].T * 0.5).tolist()}, {}, "last row"),
        ({"fl_x": 0}, {}, "non-positive focal length fl_x=0"),
        ({}, {"fl_y": -3.0}, "non-positive focal length fl_y=-3"),
        ({}, {"fl_x": None}, "missing focal length 'fl_x'"),
        ({"fl_x": "500"}, {}, "'fl_x' must be a finite number"),
        ({"camera_model": "OPENCV_FISHEYE"}, {}, "not supported"),
        ({"camera_model": "OPENCV", "k1": 0.1}, {}, "nonzero lens distortion k1"),
        ({"depth_type": "euclid"}, {}, "'depth_type' must be one of z, ray"),
        ({}, {"camera_convention": "colmap"}, "'camera_convention' must be one of"),
        ({"w": 10}, {}, "image is 8x6 pixels but the camera is 10x6"),
    ],
)
def test_frame_errors_name_transforms_and_frame(tmp_path, frame, top, message):
    simple_folder(tmp_path, frame_extra=frame, top_extra=top)
    text = error_of(load_observations, tmp_path)
    assert message in text
    assert "frames[0]" in text
    assert "transforms.json" in text or "a.png" in text or "a.npy" in text


def test_opencv_model_without_distortion_is_a_pinhole(tmp_path):
    simple_folder(tmp_path, frame_extra={"camera_model": "OPENCV", "k1": 0.0, "p2": 0})
    assert load_observations(tmp_path).frames[0].camera.fx == 9.0


def test_duplicate_explicit_names(tmp_path):
    simple_folder(tmp_path, frame_extra={"name": "x"})
    data = json.loads((tmp_path / "transforms.json").read_text())
    data["frames"].append(data["frames"][0])
    (tmp_path / "transforms.json").write_text(json.dumps(data))
    assert "frames[1]: duplicate frame name 'x'" in error_of(load_observations, tmp_path)


def test_unreadable_image_names_the_file(tmp_path):
    simple_folder(tmp_path)
    (tmp_path / "images/a.png").write_bytes(b"garbage")
    text = error_of(load_observations, tmp_path)
    assert "a.png" in text and "cannot read image" in text and "frames[0]" in text


def test_unreadable_depth_names_the_file(tmp_path):
    simple_folder(tmp_path)
    (tmp_path / "depth/a.npy").write_bytes(b"garbage")
    text = error_of(load_observations, tmp_path)
    assert "a.npy" in text and "cannot read depth map" in text


def test_greyscale_image_is_rejected(tmp_path):
    simple_folder(tmp_path)
    Image.fromarray(np.zeros((H, W), np.uint8)).save(tmp_path / "images/a.png")
    text = error_of(load_observations, tmp_path)
    assert "a.png" in text and "greyscale" in text


def test_depth_size_mismatch_names_the_depth_file(tmp_path):
    simple_folder(tmp_path)
    np.save(tmp_path / "depth/a.npy", np.ones((H + 1, W), np.float32))
    text = error_of(load_observations, tmp_path)
    assert "a.npy" in text and "depth map is 8x7" in text


@pytest.mark.parametrize(
    "array, message",
    [
        (np.ones((H, W), np.uint16), "not float metres"),
        (np.ones((H, W, 3), np.float32), "expected (H, W)"),
        (np.zeros((H, W), np.float32), "every pixel of the depth map is missing"),
    ],
)
def test_bad_npy_depth(tmp_path, array, message):
    simple_folder(tmp_path)
    np.save(tmp_path / "depth/a.npy", array)
    text = error_of(load_observations, tmp_path)
    assert "a.npy" in text and message in text


def test_8bit_depth_png_is_rejected(tmp_path):
    simple_folder(tmp_path, frame_extra={"depth_file_path": "depth/a.png"})
    Image.fromarray(np.ones((H, W), np.uint8)).save(tmp_path / "depth/a.png")
    text = error_of(load_observations, tmp_path)
    assert "a.png" in text and "16-bit greyscale" in text


def test_unsupported_depth_type(tmp_path):
    simple_folder(tmp_path, frame_extra={"depth_file_path": "depth/a.tif"})
    (tmp_path / "depth/a.tif").write_bytes(b"")
    assert "unsupported depth file type '.tif'" in error_of(load_observations, tmp_path)


def test_depth_below_zero_is_missing_with_a_warning(tmp_path, caplog):
    """docs/observations.md: 0, negative, NaN or inf in a file is no measurement; a negative
    value is said, since it may be a map with an offset rather than a sensor's mark."""
    import logging

    from sppl.data.observations import load_observations

    (tmp_path / "images").mkdir()
    (tmp_path / "depth").mkdir()
    Image.fromarray(np.full((6, 8, 3), 128, np.uint8)).save(tmp_path / "images" / "a.png")
    depth = np.full((6, 8), 2.0, np.float32)
    depth[0] = -1.0
    depth[1, :3] = -0.25
    np.save(tmp_path / "depth" / "a.npy", depth)
    (tmp_path / "transforms.json").write_text(json.dumps({"fl_x": 9.0, "w": 8, "h": 6, "frames": [
        {"file_path": "images/a.png", "depth_file_path": "depth/a.npy",
         "transform_matrix": look_at([3.0, -2.0, 1.5], [0.0, 0.0, 0.5]).tolist()}]}))
    with caplog.at_level(logging.WARNING, logger="sppl.data.observations"):
        frame = load_observations(tmp_path).frames[0]
    assert not frame.depth_valid[0].any() and not frame.depth_valid[1, :3].any()
    assert frame.depth_valid.sum() == 48 - 11 and np.isnan(frame.depth[0]).all()
    assert "11 depth pixels below zero (down to -1 m) taken as missing" in caplog.text
    caplog.clear()
    np.save(tmp_path / "depth" / "a.npy", np.full((6, 8), 2.0, np.float32))
    with caplog.at_level(logging.WARNING, logger="sppl.data.observations"):
        load_observations(tmp_path)
    assert "below zero" not in caplog.text
