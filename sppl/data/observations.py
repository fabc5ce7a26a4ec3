"""Observation folders: cameras, RGB images and depth maps in nerfstudio's ``transforms.json``.

A folder holds ``transforms.json`` plus the files it names::

    {"fl_x": 500, "fl_y": 500, "cx": 320, "cy": 240, "w": 640, "h": 480,   # or per frame
     "depth_max": 10.0, "depth_type": "z", "integer_depth_scale": 0.001,   # optional
     "frames": [{"file_path": "images/cam0.png", "depth_file_path": "depth/cam0.npy",
                 "transform_matrix": [[...], [...], [...], [0, 0, 0, 1]]}]}

Conventions (those of ``sppl.data.camera``; existing nerfstudio / instant-ngp datasets load as they are):

- ``transform_matrix`` is camera-to-world in OpenGL axes (+x right, +y up, looking along -z).
  ``"camera_convention": "opencv"`` marks OpenCV/COLMAP-axis matrices, converted here and only here.
  A frame may give ``"look_at": {"eye": [..], "target": [..], "up": [0, 0, 1]}`` instead.
- Intrinsics ``fl_x fl_y cx cy w h`` are pixels, origin at the image's top-left corner; a per-frame
  value wins over the top-level one. ``camera_angle_x`` (radians, NeRF-synthetic) stands in for
  ``fl_x``; ``fl_y`` defaults to ``fl_x``, ``cx, cy`` to the image centre, ``w, h`` to the image
  size.
  Only pinhole cameras are accepted: the renderer cannot model lens distortion.
- RGB: float32 (H, W, 3) in [0, 1], the file's 8-bit values / 255 or 16-bit values / 65535, with
  no gamma conversion (an sRGB-encoded file stays sRGB-encoded). Alpha is dropped.
- Depth: float32 (H, W) metres. ``depth_type`` says which distance a pixel holds: ``"z"`` (default;
  along the optical axis, as RGB-D sensors and nerfstudio store it) or ``"ray"`` (from the optical
  centre along the pixel's ray, the thesis's definition). ``.npy`` files hold float metres, 16-bit
  PNGs integer units of ``integer_depth_scale`` metres (default 0.001: millimetres), ``.exr`` files
  float metres in channel ``Z`` (needs ``pip install openexr``). A pixel that is 0, negative, NaN
  or inf in the file is missing: NaN in ``depth`` and False in ``depth_valid``, so the likelihood
  leaves it out. Values beyond ``depth_max`` (default 10 m) are clipped to it.

Every problem a user can cause is an ``ObservationError`` naming the file and the frame.
"""

from __future__ import annotations

import json
import logging
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from ..errors import ObservationError, Span
from .camera import CV_TO_GL, DEPTH_TYPES, Camera, look_at

MODALITIES = ("rgb", "depth")
DEFAULT_DEPTH_MAX = 10.0
DEFAULT_INTEGER_DEPTH_SCALE = 0.001  # metres per unit of a 16-bit depth PNG: millimetres
CONVENTIONS = ("opengl", "opencv")
TOLERANCE = 1e-4  # on a pose's rotation and last row; float32 exports are far inside it

# OPENCV with every coefficient zero is an exact pinhole, and ns-process-data writes it that way.
_PINHOLE_MODELS = ("PINHOLE", "SIMPLE_PINHOLE", "OPENCV")
_DISTORTION_KEYS = ("k1", "k2", "k3", "k4", "p1", "p2")
_GREY_MODES = ("1", "L", "LA", "La", "I", "I;16", "I;16B", "I;16L", "I;16N", "F")
_INTEGER_DEPTH_MODES = ("I;16", "I;16B", "I;16L", "I;16N", "I")
_MM = 0.001

log = logging.getLogger(__name__)


@dataclass
class Frame:
    """One camera's view: its camera and whichever of RGB and depth it observed."""

    camera: Camera
    rgb: np.ndarray | None = None  # (H, W, 3) float32 in [0, 1]
    depth: np.ndarray | None = None  # (H, W) float32 metres, NaN where missing
    depth_valid: np.ndarray | None = None  # (H, W) bool, False where depth is missing
    rgb_path: Path | None = None
    depth_path: Path | None = None

    @property
    def name(self) -> str:
        return self.camera.name

    @property
    def modalities(self) -> tuple[str, ...]:
        return tuple(m for m, a in zip(MODALITIES, (self.rgb, self.depth)) if a is not None)


@dataclass
class Observations:
    root: Path
    frames: list[Frame]

    @property
    def cameras(self) -> list[Camera]:
        return [f.camera for f in self.frames]

    def __len__(self) -> int:
        return len(self.frames)


@dataclass(frozen=True)
class CameraSpec:
    """A camera to simulate, and which modalities (``"rgb"``, ``"depth"``) it records."""

    camera: Camera
    modalities: tuple[str, ...] = MODALITIES


# ----------------------------------------------------------------------------------------------
# Loading


def load_observations(folder: str | Path) -> Observations:
    """Read ``folder/transforms.json`` and every image and depth map it names.

    ``folder`` may also be the path of the JSON file itself; file paths are relative to its folder.
    """
    path = _transforms_path(folder)
    data = _read_json(path)
    names: set[str] = set()
    frames = []
    for index, entry in enumerate(data["frames"]):
        r = _FrameReader(path, data, entry, index)
        frames.append(_load_frame(r, names))
    return Observations(root=path.parent, frames=frames)


def load_cameras(path: str | Path) -> list[CameraSpec]:
    """Read a cameras file for ``simulate``: the ``transforms.json`` layout, with no files needed.

    Returns one ``CameraSpec(camera, modalities)`` per frame. A frame's modalities are its
    ``"modalities"`` list if given, else those it names files for (so an observation folder
    written by ``write_observations`` reproduces itself), else both ``("rgb", "depth")``.
    ``w`` and ``h`` are required, as there are no images to take them from. ``path`` may be a
    folder holding ``transforms.json``.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "transforms.json"
    data = _read_json(path)
    names: set[str] = set()
    specs = []
    for index, entry in enumerate(data["frames"]):
        r = _FrameReader(path, data, entry, index)
        files = [r.entry.get(k) for k in ("file_path", "depth_file_path", "depth_path")]
        name = _frame_name(r, [f for f in files if isinstance(f, str)], names)
        specs.append(CameraSpec(_camera(r, name, None), _modalities(r)))
    return specs


def _transforms_path(folder: str | Path) -> Path:
    folder = Path(folder)
    if folder.is_file():
        return folder
    if not folder.exists():
        raise ObservationError(
            "observation folder not found", path=folder, hint="check the path given to --obs"
        )
    path = folder / "transforms.json"
    if folder.is_dir() and not any(folder.iterdir()):
        raise ObservationError(
            "observation folder is empty", path=folder,
            hint="it should hold transforms.json (nerfstudio layout) and the images and depth "
            "maps it names; `sppl simulate` writes one",
        )
    if not path.is_file():
        raise ObservationError(
            "no transforms.json in this folder",
            path=folder,
            hint="an observation folder holds transforms.json (nerfstudio layout) and the "
            "images and depth maps it names",
        )
    return path


def _read_json(path: Path) -> dict:
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ObservationError("file not found", path=path) from None
    except (OSError, UnicodeDecodeError) as e:
        raise ObservationError(f"cannot read the file: {e}", path=path) from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as e:
        raise ObservationError(
            f"not valid JSON: {e.msg}", path=path, span=Span(e.lineno, e.colno)
        ) from None
    if not isinstance(data, dict):
        raise ObservationError("must hold a JSON object with a 'frames' list", path=path)
    if "frames" not in data:
        raise ObservationError(
            "missing key 'frames'", path=path, hint="a list with one entry per camera"
        )
    if not isinstance(data["frames"], list):
        raise ObservationError("'frames' must be a list with one entry per camera", path=path)
    if not data["frames"]:
        raise ObservationError("'frames' is empty", path=path, hint="add at least one camera")
    return data


class _FrameReader:
    """Typed access to one entry of ``frames``, with the file's top-level values as defaults."""

    def __init__(self, path: Path, top: dict, entry: Any, index: int) -> None:
        self.path, self.top, self.entry, self.index = path, top, entry, index
        if not isinstance(entry, dict):
            raise self.error("must be a JSON object")

    def error(self, message: str, hint: str | None = None, path: Path | None = None):
        message = f"frames[{self.index}]: {message}"
        return ObservationError(message, path=path or self.path, hint=hint)

    def has(self, key: str) -> bool:
        return key in self.entry or key in self.top

    def get(self, key: str, default: Any = None) -> Any:
        # Per-frame values win over top-level ones, as in nerfstudio.
        return self.entry[key] if key in self.entry else self.top.get(key, default)

    def number(self, key: str, default: Any = None, *, positive: bool = False) -> Any:
        scope = self.entry if key in self.entry else self.top
        if key not in scope:
            return default
        value = self.as_number(key, scope[key])
        if positive and value <= 0:
            raise self.error(f"'{key}' must be positive, got {value}")
        return value

    def as_number(self, key: str, value: Any) -> float:
        is_number = isinstance(value, (int, float)) and not isinstance(value, bool)
        if not is_number or not math.isfinite(value):
            raise self.error(f"'{key}' must be a finite number, got {json.dumps(value)}")
        return float(value)

    def choice(self, key: str, options: tuple[str, ...], default: str) -> str:
        value = self.get(key, default)
        if not isinstance(value, str) or value.lower() not in options:
            choices = ", ".join(options)
            raise self.error(f"'{key}' must be one of {choices}; got {json.dumps(value)}")
        return value.lower()


def _load_frame(r: _FrameReader, names: set[str]) -> Frame:
    rgb_key = "file_path" if r.entry.get("file_path") is not None else None
    depth_keys = [k for k in ("depth_file_path", "depth_path") if r.entry.get(k) is not None]
    depth_key = depth_keys[0] if depth_keys else None
    if rgb_key is None and depth_key is None:
        raise r.error(
            "has neither an image nor a depth map",
            hint="give 'file_path' for RGB and/or 'depth_file_path' for depth",
        )
    rgb_path = _resolve(r, rgb_key) if rgb_key else None
    depth_path = _resolve(r, depth_key) if depth_key else None
    rgb = _read_rgb(r, rgb_path) if rgb_path else None
    scale = r.number("integer_depth_scale", DEFAULT_INTEGER_DEPTH_SCALE, positive=True)
    raw_depth = _read_depth(r, depth_path, scale) if depth_path else None

    files = ((rgb_path, rgb), (depth_path, raw_depth))
    sizes = [(file, array.shape[:2]) for file, array in files if array is not None]
    name = _frame_name(r, [r.entry[k] for k in (rgb_key, depth_key) if k], names)
    camera = _camera(r, name, sizes[0][1])
    for file, (h, w) in sizes:
        if (w, h) != (camera.width, camera.height):
            raise r.error(
                f"{'image' if file == rgb_path else 'depth map'} is {w}x{h} pixels but the camera "
                f"is {camera.width}x{camera.height}",
                hint="fix 'w' and 'h' in transforms.json or resize the file",
                path=file,
            )

    depth = valid = None
    if raw_depth is not None:
        with np.errstate(invalid="ignore"):
            valid = np.isfinite(raw_depth) & (raw_depth > 0)
            negative = int(np.sum(raw_depth < 0))
        if negative:  # a sensor's "no reading" mark, or a map with an offset: say which
            log.warning("%s: frames[%d]: %d depth pixel%s below zero (down to %.3g m) taken as "
                        "missing, no measurement", depth_path, r.index, negative,
                        "s" if negative != 1 else "", float(np.nanmin(raw_depth)))
        if not valid.any():
            raise r.error(
                "every pixel of the depth map is missing (0, NaN or inf)",
                hint="check the file and integer_depth_scale, or drop depth_file_path",
                path=depth_path,
            )
        _check_depth_scale(r, raw_depth[valid], camera, depth_path)
        depth = np.where(valid, np.minimum(raw_depth, camera.depth_max), np.nan).astype(np.float32)
    return Frame(camera, rgb, depth, valid, rgb_path, depth_path)


def _check_depth_scale(r: _FrameReader, depth: np.ndarray, camera: Camera, path: Path) -> None:
    """A depth map in the wrong unit is all beyond the camera's range or all in front of its
    near plane; either way it holds nothing the renderer can match."""
    scale_hint = ("store float metres in .npy, or integer units of integer_depth_scale metres "
                  "(default 0.001, millimetres) in a 16-bit PNG")
    if depth.min() >= camera.depth_max:
        raise r.error(
            f"every depth pixel is at or beyond depth_max = {camera.depth_max:g} m (the nearest "
            f"is {depth.min():.4g}): is the map in millimetres?",
            hint=f"{scale_hint}; or raise depth_max", path=path,
        )
    if depth.max() < camera.near:
        raise r.error(
            f"every depth pixel is nearer than near = {camera.near:g} m (the farthest is "
            f"{depth.max():.3g}): is the map in the wrong unit?",
            hint=scale_hint, path=path,
        )


def _frame_name(r: _FrameReader, files: list[str], names: set[str]) -> str:
    explicit = r.entry.get("name")
    if explicit is not None:
        if not isinstance(explicit, str) or not explicit:
            raise r.error(f"'name' must be a non-empty string, got {json.dumps(explicit)}")
        if explicit in names:
            raise r.error(f"duplicate frame name '{explicit}'", hint="frame names must be unique")
        name = explicit
    else:
        # File stems can repeat across sub-folders (cam0/0001.png, cam1/0001.png).
        name = Path(files[0]).stem if files and Path(files[0]).stem else f"frame{r.index}"
        while name in names:
            name = f"{name}_{r.index}"
    names.add(name)
    return name


def _resolve(r: _FrameReader, key: str) -> Path:
    value = r.entry[key]
    if not isinstance(value, str) or not value:
        raise r.error(f"'{key}' must be a file path, got {json.dumps(value)}")
    path = r.path.parent / value
    if not path.exists() and not path.suffix:
        # NeRF-synthetic writes file_path without its extension.
        found = [path.with_suffix(s) for s in (".png", ".jpg", ".jpeg")]
        path = next((p for p in found if p.exists()), path)
    if not path.is_file():
        raise r.error(
            f"{key} '{value}' not found (looked for {path})",
            hint="paths are relative to the folder holding transforms.json",
        )
    return path


def _modalities(r: _FrameReader) -> tuple[str, ...]:
    if r.has("modalities"):
        given = r.get("modalities")
        ok = isinstance(given, list) and given and all(m in MODALITIES for m in given)
        if not ok or len(set(given)) != len(given):
            raise r.error(
                f"'modalities' must be a non-empty list of distinct 'rgb' and 'depth', "
                f"got {json.dumps(given)}"
            )
        return tuple(m for m in MODALITIES if m in given)
    named = (r.entry.get("file_path"), r.entry.get("depth_file_path") or r.entry.get("depth_path"))
    if any(named):
        return tuple(m for m, f in zip(MODALITIES, named) if f)
    return MODALITIES


# ----------------------------------------------------------------------------------------------
# Cameras


def _camera(r: _FrameReader, name: str, size: tuple[int, int] | None) -> Camera:
    """``size`` is the (H, W) of the frame's files, standing in for missing ``w``/``h``."""
    _check_pinhole(r)
    width = _pixels(r, "w", None if size is None else size[1])
    height = _pixels(r, "h", None if size is None else size[0])
    fx = _focal(r, "fl_x", "camera_angle_x", width)
    fy = _focal(r, "fl_y", "camera_angle_y", height, fallback=fx)
    depth_max = r.number("depth_max", DEFAULT_DEPTH_MAX, positive=True)
    near = r.number("near", 0.01, positive=True)
    if near >= depth_max:
        raise r.error(f"'near' ({near}) must be smaller than 'depth_max' ({depth_max})")
    camera = Camera(
        name=name,
        width=width,
        height=height,
        fx=fx,
        fy=fy,
        cx=r.number("cx", width / 2),
        cy=r.number("cy", height / 2),
        c2w=_pose(r),
        depth_max=depth_max,
        depth_type=r.choice("depth_type", DEPTH_TYPES, "z"),
        near=near,
    )
    _check_principal_point(r, camera)
    _check_sees_ground(r, camera)
    return camera


def _check_principal_point(r: _FrameReader, cam: Camera) -> None:
    # Intrinsics written for another resolution (the images were resized, or w and h belong
    # to another camera) put the principal point off the image.
    if not (0 <= cam.cx <= cam.width and 0 <= cam.cy <= cam.height):
        raise r.error(
            f"principal point (cx, cy) = ({cam.cx:g}, {cam.cy:g}) lies outside the "
            f"{cam.width}x{cam.height} image",
            hint="the intrinsics seem to be for another image size: scale fl_x, fl_y, cx, cy "
            "with the images",
        )


def _check_sees_ground(r: _FrameReader, cam: Camera) -> None:
    """Every scene sppl samples stands on the ground plane z = 0; a camera that sees none of
    it almost always has its pose in another convention (y up, OpenCV axes, world-to-camera)
    rather than pointing at the sky on purpose. (Ground beyond ``depth_max`` still counts: the
    RGB image shows it, and the depth map holds it clipped.)"""
    hint = ("sppl's world is z-up with the ground at z = 0, and transform_matrix is "
            "camera-to-world in OpenGL axes: convert y-up poses, or mark OpenCV ones with "
            '"camera_convention": "opencv"')
    height = float(cam.c2w[2, 3])
    if height <= 0:
        raise r.error(f"the camera is at height z = {height:.3g} m, not above the ground "
                      "(z = 0), so it sees none of it", hint=hint)
    # The ray through pixel (u, v) is R (x, y, -1) with x, y linear in u, v; how steeply it
    # points down is linear too, so the steepest ray in the image is through a corner.
    corners = np.array([[0, 0], [cam.width, 0], [0, cam.height], [cam.width, cam.height]])
    x = (corners[:, 0] - cam.cx) / cam.fx
    y = -(corners[:, 1] - cam.cy) / cam.fy
    down = -(cam.c2w[2, :3] @ np.stack([x, y, -np.ones(4)]))
    if float(down.max()) <= 0:
        raise r.error("the camera looks entirely above the horizon and sees none of the ground "
                      "(z = 0)", hint=hint)


def _check_pinhole(r: _FrameReader) -> None:
    model = r.get("camera_model")
    if model is not None and (not isinstance(model, str) or model.upper() not in _PINHOLE_MODELS):
        raise r.error(
            f"camera_model {json.dumps(model)} is not supported: sppl renders pinhole cameras",
            hint="undistort the images first and set camera_model to PINHOLE",
        )
    for key in _DISTORTION_KEYS:
        if r.number(key, 0.0) != 0.0:
            raise r.error(
                f"nonzero lens distortion {key}={r.get(key)}: sppl renders pinhole cameras",
                hint="undistort the images first and remove the distortion coefficients",
            )


def _pixels(r: _FrameReader, key: str, default: int | None) -> int:
    value = r.number(key, None, positive=True)
    if value is None:
        if default is None:
            raise r.error(f"missing '{key}'", hint="the image size in pixels, 'w' and 'h'")
        return int(default)
    if value != int(value):
        raise r.error(f"'{key}' must be a whole number of pixels, got {value}")
    return int(value)


def _focal(r: _FrameReader, key: str, angle_key: str, size: int, fallback: float | None = None):
    # Per frame first, then top level, so that a frame's own field of view beats a top-level
    # focal length.
    for scope in (r.entry, r.top):
        if key in scope:
            value = r.as_number(key, scope[key])
            if value <= 0:
                raise r.error(
                    f"non-positive focal length {key}={value}", hint="focal lengths are pixels, > 0"
                )
            return value
        if angle_key in scope:
            angle = r.as_number(angle_key, scope[angle_key])
            if not 0 < angle < math.pi:
                raise r.error(f"'{angle_key}' must be in (0, pi) radians, got {angle}")
            return 0.5 * size / math.tan(0.5 * angle)
    if fallback is not None:
        return fallback
    raise r.error(
        f"missing focal length '{key}'", hint=f"give '{key}' in pixels or '{angle_key}' in radians"
    )


def _pose(r: _FrameReader) -> np.ndarray:
    if "transform_matrix" in r.entry and "look_at" in r.entry:
        raise r.error("give either 'transform_matrix' or 'look_at', not both")
    if "look_at" in r.entry:
        return _look_at(r, r.entry["look_at"])
    if "transform_matrix" not in r.entry:
        raise r.error(
            "missing 'transform_matrix'",
            hint="a 4x4 camera-to-world matrix in OpenGL axes, or 'look_at' with eye and target",
        )
    try:
        m = np.array(r.entry["transform_matrix"], dtype=float)
    except (TypeError, ValueError):
        raise r.error("'transform_matrix' must be a 4x4 list of numbers") from None
    if m.shape != (4, 4):
        raise r.error(f"'transform_matrix' has shape {m.shape} but must be 4x4")
    if not np.isfinite(m).all():
        raise r.error("'transform_matrix' contains NaN or inf")
    if np.abs(m[3] - [0, 0, 0, 1]).max() > TOLERANCE:
        raise r.error(f"'transform_matrix' last row is {m[3].tolist()}, not [0, 0, 0, 1]")
    rot = m[:3, :3]
    error = np.abs(rot.T @ rot - np.eye(3)).max()
    if error > TOLERANCE:
        raise r.error(
            f"the rotation of 'transform_matrix' is not orthonormal (|R^T R - I| = {error:.2g})",
            hint="a camera pose is a rotation and a translation, with no scale or shear",
        )
    if abs(np.linalg.det(rot) - 1.0) > TOLERANCE:
        raise r.error(
            "the rotation of 'transform_matrix' has determinant -1 (a reflection)",
            hint="check that one axis was not flipped when converting between OpenCV and OpenGL",
        )
    if r.choice("camera_convention", CONVENTIONS, "opengl") == "opencv":
        m = m @ CV_TO_GL
    return m


def _look_at(r: _FrameReader, spec: Any) -> np.ndarray:
    if not isinstance(spec, dict) or not {"eye", "target"} <= spec.keys():
        raise r.error("'look_at' must be an object with 'eye', 'target' and optionally 'up'")
    vectors = []
    for key in ("eye", "target", "up"):
        try:
            v = np.array(spec.get(key, [0.0, 0.0, 1.0]), dtype=float)
        except (TypeError, ValueError):
            v = None
        if v is None or v.shape != (3,) or not np.isfinite(v).all():
            raise r.error(f"'look_at.{key}' must be a list of 3 numbers")
        vectors.append(v)
    eye, target, up = vectors
    if np.linalg.norm(eye - target) < 1e-9:
        raise r.error("'look_at' eye and target are the same point")
    try:
        return look_at(eye, target, up)
    except ValueError:
        raise r.error("'look_at.up' is parallel to the viewing direction") from None


# ----------------------------------------------------------------------------------------------
# Files


def _read_rgb(r: _FrameReader, path: Path) -> np.ndarray:
    try:
        with Image.open(path) as im:
            rawmode = im.tile[0][3] if len(im.tile) == 1 else None
            im.load()
            if im.mode in _INTEGER_DEPTH_MODES:
                raise r.error(
                    f"image is 16-bit greyscale ({im.mode}), like a depth map, not an RGB image",
                    hint="give it as depth_file_path, or give an 8- or 16-bit colour image as "
                    "file_path",
                    path=path,
                )
            if im.mode in _GREY_MODES:
                raise r.error(
                    f"image is greyscale ({im.mode}); an RGB observation needs colour channels",
                    hint="give a depth map as depth_file_path, or convert the image to RGB",
                    path=path,
                )
            if im.mode not in ("RGB", "RGBA"):
                im = im.convert("RGB")
            rgb = np.asarray(im)[..., :3]
    except ObservationError:
        raise
    except (OSError, ValueError, SyntaxError, Image.DecompressionBombError) as e:
        raise r.error(f"cannot read image: {e}", path=path) from None
    if rawmode in ("RGB;16B", "RGBA;16B"):
        low = _low_bytes(path, rawmode)
        if low is not None:
            return ((rgb.astype(np.float32) * 256 + low) / 65535).astype(np.float32)
    return (rgb / np.float32(255)).astype(np.float32)


def _low_bytes(path: Path, rawmode: str) -> np.ndarray | None:
    """Low bytes of a 16-bit colour PNG, or None (then the high bytes alone give 8-bit precision).

    Pillow has no 16-bit colour mode and keeps only the high byte of each sample; decoding again
    with the little-endian raw mode makes it keep the low byte instead.
    """
    try:
        with Image.open(path) as im:
            codec, extents, offset, _ = im.tile[0]
            im.tile = [(codec, extents, offset, rawmode.replace("16B", "16L"))]
            im.load()
            return np.asarray(im)[..., :3].astype(np.float32)
    except Exception:  # an internal of Pillow's; 8-bit precision is still a correct image
        return None


def _read_depth(r: _FrameReader, path: Path, scale: float) -> np.ndarray:
    """The depth map in metres as float64, before masking and clipping."""
    suffix = path.suffix.lower()
    if suffix == ".npy":
        try:
            depth = np.load(path, allow_pickle=False)
        except (OSError, ValueError, EOFError) as e:  # EOFError: an empty or truncated file
            raise r.error(f"cannot read depth map: {e}", path=path) from None
        if not np.issubdtype(depth.dtype, np.floating):
            raise r.error(
                f"depth .npy holds {depth.dtype} values, not float metres",
                hint="save float32 metres, or integer units as a 16-bit PNG",
                path=path,
            )
    elif suffix == ".png":
        try:
            with Image.open(path) as im:
                if im.mode not in _INTEGER_DEPTH_MODES:
                    kind = {"L": "8-bit greyscale", "1": "1-bit", "P": "8-bit palette",
                            "RGB": "8-bit colour", "RGBA": "8-bit colour"}.get(im.mode, "")
                    raise r.error(
                        f"depth PNG is {kind + ' ' if kind else ''}(mode {im.mode}), not 16-bit "
                        "greyscale",
                        hint="store integer units of integer_depth_scale metres (default 0.001, "
                        "millimetres) in one 16-bit channel, or float metres in .npy",
                        path=path,
                    )
                depth = np.asarray(im, dtype=np.float64) * scale
        except ObservationError:
            raise
        except (OSError, ValueError, SyntaxError, Image.DecompressionBombError) as e:
            raise r.error(f"cannot read depth map: {e}", path=path) from None
    elif suffix == ".exr":
        depth = _read_exr(r, path)
    else:
        raise r.error(
            f"unsupported depth file type '{path.suffix}'",
            hint="use .npy (float metres), 16-bit .png (integer_depth_scale) or .exr",
            path=path,
        )
    if depth.ndim == 3 and depth.shape[2] == 1:
        depth = depth[..., 0]
    if depth.ndim != 2:
        raise r.error(f"depth map has shape {depth.shape}, expected (H, W)", path=path)
    return depth.astype(np.float64)


def _read_exr(r: _FrameReader, path: Path) -> np.ndarray:
    try:
        import OpenEXR
    except ImportError:
        raise r.error(
            "cannot read .exr depth: the OpenEXR module is not installed",
            hint="pip install openexr, or convert the depth maps to .npy",
            path=path,
        ) from None
    try:
        with OpenEXR.File(str(path)) as f:
            channels = {name: np.array(c.pixels) for name, c in f.channels().items()}
    except Exception as e:  # OpenEXR raises bare RuntimeErrors and others
        raise r.error(f"cannot read depth map: {e}", path=path) from None
    # Blender's multilayer files call it e.g. "ViewLayer.Depth.Z".
    z = [n for n in channels if n == "Z" or n.endswith(".Z")]
    if len(z) != 1 and len(channels) != 1:
        raise r.error(
            f"EXR has no single 'Z' channel (channels: {', '.join(sorted(channels))})", path=path
        )
    return channels[z[0] if len(z) == 1 else next(iter(channels))]


# ----------------------------------------------------------------------------------------------
# Writing


def write_observations(
    folder: str | Path, frames: list[Frame] | Observations, *, depth_format: str = "npy"
) -> Path:
    """Write ``frames`` as an observation folder that ``load_observations`` reads back.

    Images go to ``images/<name>.png`` (8-bit; values clipped to [0, 1] and rounded), depth to
    ``depth/<name>.npy`` (float32 metres, NaN where missing) or, with ``depth_format="png"``,
    ``depth/<name>.png`` (uint16 millimetres, 0 where missing). A frame's modalities are the files
    written for it. ``transforms.json`` gets per-frame intrinsics, ``depth_max``, ``depth_type`` and
    OpenGL camera-to-world matrices, and is written last, so an interrupted write leaves no folder
    that loads. Returns the folder.
    """
    if depth_format not in ("npy", "png"):
        raise ObservationError(f"depth_format must be 'npy' or 'png', got {depth_format!r}")
    frames = list(frames.frames if isinstance(frames, Observations) else frames)
    if not frames:
        raise ObservationError("no frames to write", path=folder)
    root = Path(folder)
    root.mkdir(parents=True, exist_ok=True)
    stems: set[str] = set()
    entries = []
    for index, frame in enumerate(frames):
        cam = frame.camera
        stem = _file_stem(cam.name, index, stems)
        entry: dict[str, Any] = {"name": cam.name}
        if frame.rgb is None and frame.depth is None:
            raise ObservationError(f"frame '{cam.name}' has neither rgb nor depth to write")
        if frame.rgb is not None:
            entry["file_path"] = f"images/{stem}.png"
            _write_rgb(root / entry["file_path"], frame)
        if frame.depth is not None:
            entry["depth_file_path"] = f"depth/{stem}.{depth_format}"
            _write_depth(root / entry["depth_file_path"], frame, depth_format)
        entry.update(
            w=cam.width, h=cam.height, fl_x=float(cam.fx), fl_y=float(cam.fy),
            cx=float(cam.cx), cy=float(cam.cy), depth_max=float(cam.depth_max),
            depth_type=cam.depth_type, near=float(cam.near),
            transform_matrix=np.asarray(cam.c2w, dtype=float).tolist(),
        )  # fmt: skip
        entries.append(entry)
    transforms: dict[str, Any] = {"camera_convention": "opengl"}
    if depth_format == "png":
        transforms["integer_depth_scale"] = _MM
    transforms["frames"] = entries
    tmp = root / "transforms.json.tmp"
    tmp.write_text(json.dumps(transforms, indent=2) + "\n", encoding="utf-8")
    os.replace(tmp, root / "transforms.json")
    return root


def _file_stem(name: str, index: int, stems: set[str]) -> str:
    # The name is kept in transforms.json; the file name only has to be safe and unique, also
    # on case-insensitive file systems.
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", name).lstrip(".") or f"frame{index}"
    while stem.lower() in stems:
        stem = f"{stem}_{index}"
    stems.add(stem.lower())
    return stem


def _check_shape(frame: Frame, array: np.ndarray, shape: tuple[int, ...], what: str) -> None:
    if array.shape != shape:
        raise ObservationError(
            f"frame '{frame.name}': {what} has shape {array.shape}, expected {shape} for its camera"
        )


def _write_rgb(path: Path, frame: Frame) -> None:
    cam = frame.camera
    rgb = np.asarray(frame.rgb, dtype=np.float64)
    _check_shape(frame, rgb, (cam.height, cam.width, 3), "rgb")
    pixels = np.rint(np.clip(np.nan_to_num(rgb), 0.0, 1.0) * 255).astype(np.uint8)
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(pixels, mode="RGB").save(path)


def _write_depth(path: Path, frame: Frame, depth_format: str) -> None:
    cam = frame.camera
    depth = np.asarray(frame.depth, dtype=np.float64)
    _check_shape(frame, depth, (cam.height, cam.width), "depth")
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(depth) & (depth > 0)
    if frame.depth_valid is not None:
        valid &= np.asarray(frame.depth_valid, dtype=bool)
    path.parent.mkdir(parents=True, exist_ok=True)
    if depth_format == "npy":
        np.save(path, np.where(valid, depth, np.nan).astype(np.float32))
        return
    units = np.rint(np.where(valid, depth, 0.0) / _MM)
    if units.max() > np.iinfo(np.uint16).max:
        raise ObservationError(
            f"frame '{frame.name}': depth up to {depth[valid].max():.3f} m does not fit a 16-bit "
            "millimetre PNG (at most 65.535 m)",
            hint="use depth_format='npy'",
        )
    units[valid] = np.maximum(units[valid], 1)  # a valid depth under 0.5 mm must not read as 0
    Image.fromarray(units.astype(np.uint16)).save(path)
