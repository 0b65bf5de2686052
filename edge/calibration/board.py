"""The calibration board: a ChArUco board lying face up on the floor, and what it tells about a camera.

A ChArUco board is a chessboard whose white squares hold ArUco markers: each detected marker
names the chessboard corners around it, so a partly hidden board still gives identified corners
with sub-pixel positions. Two uses:

- **Extrinsics** (``calibrate_pose``): with the camera's intrinsics known (site file, OAK
  device), the corners of one image give the board's pose in the camera (``solve_board_pose``:
  IPPE's two planar solutions and SQPnP's, each refined by Levenberg-Marquardt, the best
  kept), and the board's known place on the floor turns it into the camera's pose.
- **Intrinsics** (``calibrate_intrinsics``): corners from several views of the board give K and
  the distortion coefficients (Zhang's method, ``cv2.calibrateCamera``), for webcams.

Frames. The board frame is OpenCV's ``CharucoBoard`` object frame: origin at the board's outer
top-left corner as ``generateImage`` draws it, x along the first row, y down the image, z into
the board. Lying face up at floor point (X, Y) with yaw ``psi``::

    p_world = (X, Y, 0) + Rz(psi) @ diag(1, -1, -1) @ p_board

so the board's x axis points along ``psi`` on the floor, its y axis 90 degrees clockwise of it,
and its z axis into the floor. The camera follows ``edge.camera``: world-from-camera rotation
and optical centre (REP-103 world, OpenCV camera frame).

``render_board`` draws the board on the floor as a given camera sees it (perspective,
distortion, anti-aliasing, blur, lighting, sensor noise): the tests and the accuracy script
check the calibration against cameras whose pose is known exactly.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final, cast

import cv2
import numpy as np
from numpy.typing import NDArray

from superbody.edge.camera import Camera

__all__ = ["DICTIONARIES", "MIN_CORNERS", "MIN_VIEWS", "MAX_REPROJECTION_PX", "MAX_OBLIQUE_DEG", "BoardError", "BoardSpec", "Corners", "BoardPose", "PoseFit", "IntrinsicsFit", "parse_squares", "make_board", "board_to_world", "detect_corners", "solve_board_pose", "camera_pose_in_world", "calibrate_pose", "pose_from_corners", "calibrate_intrinsics"]


def _dictionary_names() -> tuple[str, ...]:
    """cv2.aruco's DICT_* names, one per dictionary: OpenCV's own spelling (DICT_APRILTAG_36h11)."""
    by_value: dict[int, str] = {}
    for name in sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_")):
        value = getattr(cv2.aruco, name)
        if value not in by_value or name != name.upper():
            by_value[value] = name
    return tuple(sorted(by_value.values()))


# OpenCV's predefined ArUco dictionaries; names are matched ignoring case.
DICTIONARIES: Final[tuple[str, ...]] = _dictionary_names()
# A planar pose has 6 unknowns and PnP needs 4 points; 6 leave a residual to judge the fit by.
MIN_CORNERS: Final[int] = 6
# Views of a planar target that Zhang's method needs for K (with distortion) to be well posed.
MIN_VIEWS: Final[int] = 4
# A pose whose corners reproject worse than this is not trusted (wrong intrinsics or board size).
MAX_REPROJECTION_PX: Final[float] = 3.0
# Beyond this angle between the line of sight and the board's normal, depth is poorly observed.
MAX_OBLIQUE_DEG: Final[float] = 80.0
_SQUARES_RE: Final = re.compile(r"^\s*(\d+)\s*[xX]\s*(\d+)\s*$")


class BoardError(ValueError):
    """The board cannot be used: invalid spec, too few corners, a degenerate or poor view."""


@dataclass(frozen=True)
class BoardSpec:
    """A printed ChArUco board.

    Attributes:
        squares_x: squares along the board's first row (its x axis), 2 to 64.
        squares_y: squares along its first column (its y axis), 2 to 64.
        square_m: side of a chessboard square, metres (as measured on the print).
        marker_m: side of an ArUco marker, metres, smaller than ``square_m``.
        dictionary: name of an OpenCV predefined dictionary, one of ``DICTIONARIES`` (any case).
    """

    squares_x: int
    squares_y: int
    square_m: float
    marker_m: float
    dictionary: str = "DICT_5X5_100"

    def __post_init__(self) -> None:
        for field, n in (("squares_x", self.squares_x), ("squares_y", self.squares_y)):
            if isinstance(n, bool) or not isinstance(n, int) or not 2 <= n <= 64:
                raise BoardError(f"{field} must be an integer in [2, 64], got {n!r}")
        for field, v in (("square_m", self.square_m), ("marker_m", self.marker_m)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and 0.001 <= v <= 10.0):
                raise BoardError(f"{field} must be metres in [0.001, 10], got {v!r}")
        if not self.marker_m < self.square_m:
            raise BoardError(f"marker_m must be smaller than square_m ({self.square_m}), got {self.marker_m}")
        canonical = {n.upper(): n for n in DICTIONARIES}.get(str(self.dictionary).upper())
        if canonical is None:
            raise BoardError(f"dictionary must be one of {', '.join(DICTIONARIES)}; got {self.dictionary!r}")
        object.__setattr__(self, "dictionary", canonical)  # one spelling from here on
        markers = (self.squares_x * self.squares_y) // 2
        size = _dictionary_size(self.dictionary)
        if markers > size:
            raise BoardError(
                f"a {self.squares_x}x{self.squares_y} board needs {markers} markers but {self.dictionary} has {size}"
            )

    @property
    def size_m(self) -> tuple[float, float]:
        """Width (along x) and height (along y) of the chessboard, metres."""
        return self.squares_x * self.square_m, self.squares_y * self.square_m

    @property
    def n_corners(self) -> int:
        """Number of inner chessboard corners, the points the board gives."""
        return (self.squares_x - 1) * (self.squares_y - 1)


@dataclass(frozen=True)
class Corners:
    """ChArUco corners found in one image.

    Attributes:
        ids: corner ids, shape (N,), int.
        pixels: corner positions in the image, shape (N, 2), OpenCV pixel convention.
        object_points: the same corners in the board frame, metres, shape (N, 3), z = 0.
        markers: number of ArUco markers detected.
    """

    ids: NDArray[np.int32]
    pixels: NDArray[np.float64]
    object_points: NDArray[np.float64]
    markers: int

    def __len__(self) -> int:
        return len(self.ids)


@dataclass(frozen=True)
class BoardPose:
    """The board's pose in a camera: ``p_cam = R @ p_board + t``.

    Attributes:
        R: camera-from-board rotation, shape (3, 3).
        t: board origin in the camera frame, metres, shape (3,).
        reprojection_px: RMS reprojection error of the corners, pixels.
        corners: number of corners used.
    """

    R: NDArray[np.float64]
    t: NDArray[np.float64]
    reprojection_px: float
    corners: int


@dataclass(frozen=True)
class PoseFit:
    """A camera's pose in the world from one view of the board on the floor.

    Attributes:
        position: optical centre in the world, metres, shape (3,).
        rotation: world-from-camera rotation, shape (3, 3).
        reprojection_px: RMS reprojection error of the corners, pixels.
        corners: number of corners used.
        oblique_deg: angle between the line of sight to the board's centre and its normal.
    """

    position: NDArray[np.float64]
    rotation: NDArray[np.float64]
    reprojection_px: float
    corners: int
    oblique_deg: float


@dataclass(frozen=True)
class IntrinsicsFit:
    """Intrinsics from several views of the board.

    Attributes:
        K: intrinsic matrix, shape (3, 3).
        dist: distortion coefficients (k1, k2, p1, p2, k3), shape (5,).
        rms_px: RMS reprojection error over all corners, pixels.
        image_size: (width, height) of the images.
        views: number of images used.
        skipped: indices of the images skipped for too few corners.
    """

    K: NDArray[np.float64]
    dist: NDArray[np.float64]
    rms_px: float
    image_size: tuple[int, int]
    views: int
    skipped: tuple[int, ...]


def _dictionary_size(name: str) -> int:
    return int(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name)).bytesList.shape[0])


def parse_squares(text: str) -> tuple[int, int]:
    """Parse ``"5x7"`` into (squares_x, squares_y); ``BoardError`` naming the format otherwise."""
    m = _SQUARES_RE.match(text)
    if not m:
        raise BoardError(f"squares must be COLUMNSxROWS, e.g. 5x7, got {text!r}")
    nx, ny = int(m.group(1)), int(m.group(2))
    for n in (nx, ny):
        if not 2 <= n <= 64:
            raise BoardError(f"squares must be in [2, 64] each way, got {text!r}")
    return nx, ny


def make_board(spec: BoardSpec) -> cv2.aruco.CharucoBoard:
    """The OpenCV board object for a spec (current, non-legacy pattern)."""
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, spec.dictionary))
    return cv2.aruco.CharucoBoard((spec.squares_x, spec.squares_y), spec.square_m, spec.marker_m, dictionary)


def _rz(yaw: float) -> NDArray[np.float64]:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


# Board face up on the floor: x stays, y and z (into the board) flip to -y and down.
_FACE_UP: Final = np.diag([1.0, -1.0, -1.0])


def board_to_world(origin_xy: Sequence[float], yaw: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """World-from-board transform of a board lying face up on the floor.

    Args:
        origin_xy: the board's origin (outer top-left corner) on the floor, metres, (X, Y).
        yaw: direction of the board's x axis, radians counter-clockwise from world +x.

    Returns:
        ``(R, t)``: rotation, shape (3, 3), and translation, shape (3,), with
        ``p_world = R @ p_board + t``.
    """
    return _rz(yaw) @ _FACE_UP, np.array([float(origin_xy[0]), float(origin_xy[1]), 0.0])


def detect_corners(image: NDArray[np.uint8], spec: BoardSpec, cam: Camera | None = None) -> Corners:
    """Find the board's ChArUco corners in an image.

    Args:
        image: grey (H, W) or BGR (H, W, 3) uint8 image.
        spec: the board.
        cam: the camera, if its intrinsics are known: corners are then interpolated from the
            markers with an approximate pose rather than local homographies.

    Returns:
        The corners found (possibly none).
    """
    board = make_board(spec)
    charuco = cv2.aruco.CharucoParameters()
    charuco.tryRefineMarkers = True
    if cam is not None:
        charuco.cameraMatrix = cam.K
        charuco.distCoeffs = cam.D
    detector = cv2.aruco.CharucoDetector(board, charuco, cv2.aruco.DetectorParameters())
    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image
    ch_corners, ch_ids, _, marker_ids = detector.detectBoard(grey)
    markers = 0 if marker_ids is None else len(marker_ids)
    if ch_ids is None or len(ch_ids) == 0:
        empty = np.zeros((0, 2))
        return Corners(np.zeros(0, np.int32), empty, np.zeros((0, 3)), markers)
    obj, img = board.matchImagePoints(ch_corners, ch_ids)  # type: ignore[call-overload]  # cv2 stubs: ChArUco corners come as one array, not a sequence
    return Corners(
        ids=ch_ids.reshape(-1).astype(np.int32),
        pixels=img.reshape(-1, 2).astype(np.float64),
        object_points=obj.reshape(-1, 3).astype(np.float64),
        markers=markers,
    )


def _check_spread(corners: Corners, spec: BoardSpec, need: int, what: str) -> None:
    what = f"{what}: " if what else ""
    if len(corners) < need:
        raise BoardError(
            f"{what}found {len(corners)} ChArUco corners ({corners.markers} markers), need at least {need}: "
            f"is the board ({spec.squares_x}x{spec.squares_y} {spec.dictionary}) in view, lit, flat and not too oblique?"
        )
    xy = corners.object_points[:, :2]
    # Collinear corners leave the rotation about their line unobserved.
    spread = np.linalg.svd(xy - xy.mean(axis=0), compute_uv=False)
    if spread[1] < 1e-3 * spec.square_m:
        raise BoardError(f"{what}the {len(corners)} corners found lie on one line; show more of the board")


def _fit_planar(obj: NDArray[np.float64], img: NDArray[np.float64], cam: Camera) -> tuple[NDArray, NDArray, NDArray[np.float64]]:
    """Best of IPPE's two poses and SQPnP's after Levenberg-Marquardt: (rvec, tvec, residuals (N,) px)."""
    starts = []
    # IPPE gives both planar poses; SQPnP (global for any points) covers the exactly symmetric
    # views where IPPE's homography step returns NaN.
    for flags in (cv2.SOLVEPNP_IPPE, cv2.SOLVEPNP_SQPNP):
        _, rvecs, tvecs, _ = cv2.solvePnPGeneric(obj, img, cam.K, cam.D, flags=flags)
        starts += [(r, t) for r, t in zip(rvecs, tvecs) if np.isfinite(r).all() and np.isfinite(t).all()]
    if not starts:
        raise BoardError("no pose fits the corners found")
    best = None
    for rvec, tvec in starts:
        rvec, tvec = cv2.solvePnPRefineLM(obj, img, cam.K, cam.D, rvec.copy(), tvec.copy())
        proj, _ = cv2.projectPoints(obj, rvec, tvec, cam.K, cam.D)
        residuals = np.linalg.norm((proj - img).reshape(-1, 2), axis=1)
        if tvec[2, 0] > 0 and (best is None or np.sum(residuals**2) < np.sum(best[2] ** 2)):
            best = (rvec, tvec, residuals)
    if best is None:
        raise BoardError("every pose that fits the corners puts the board behind the camera")
    return best


# A corner further than this from the fit, and than 3 times the median, is dropped: a
# marker's border blurred into the corner (far, small squares) pulls it by up to a pixel.
_OUTLIER_PX: Final[float] = 0.4


def solve_board_pose(object_points: NDArray, pixels: NDArray, cam: Camera) -> BoardPose:
    """The board's pose in the camera from its corners.

    IPPE gives both poses a planar target allows (SQPnP one more); each is refined by
    Levenberg-Marquardt on the reprojection error and the best is kept. Corners that fit much worse than the
    rest (over 0.4 px and 3 times the median) are dropped and the pose solved again, up to
    three times, as long as ``MIN_CORNERS`` remain.

    Args:
        object_points: corners in the board frame, shape (N, 3), z = 0, N >= 4.
        pixels: their image positions, shape (N, 2).
        cam: the camera (intrinsics and distortion are used, not its pose).

    Returns:
        The pose, the RMS reprojection error of the corners kept and their number.
    """
    obj = np.asarray(object_points, dtype=np.float64).reshape(-1, 1, 3)
    img = np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
    rvec, tvec, residuals = _fit_planar(obj, img, cam)
    for _ in range(3):
        keep = residuals <= max(_OUTLIER_PX, 3.0 * float(np.median(residuals)))
        if keep.all() or keep.sum() < MIN_CORNERS:
            break
        obj, img = obj[keep], img[keep]
        rvec, tvec, residuals = _fit_planar(obj, img, cam)
    rms = float(np.sqrt(np.mean(residuals**2)))
    return BoardPose(R=cast("NDArray[np.float64]", cv2.Rodrigues(rvec)[0]), t=tvec.reshape(3), reprojection_px=rms, corners=len(obj))


def camera_pose_in_world(
    pose: BoardPose, origin_xy: Sequence[float], yaw: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The camera's pose in the world from the board's pose in the camera and on the floor.

    Returns:
        ``(rotation, position)``: world-from-camera rotation, shape (3, 3), and optical centre
        in the world, shape (3,).
    """
    R_wb, t_wb = board_to_world(origin_xy, yaw)
    # Camera in the board frame: p_board = R^T (p_cam - t), so its centre is -R^T t.
    R_bc = pose.R.T
    c_b = -R_bc @ pose.t
    R_wc = R_wb @ R_bc
    u, _, vt = np.linalg.svd(R_wc)  # re-orthonormalise against float drift
    return u @ vt, R_wb @ c_b + t_wb


def calibrate_pose(image: NDArray[np.uint8], spec: BoardSpec, cam: Camera, origin_xy: Sequence[float], yaw: float) -> PoseFit:
    """A camera's pose in the world from one image of the board lying on the floor.

    Args:
        image: grey (H, W) or BGR (H, W, 3) uint8 image from the camera, at its site size.
        spec: the board.
        cam: the camera, with its intrinsics (its pose is not used).
        origin_xy: the board's origin on the floor, metres.
        yaw: the direction of the board's x axis, radians counter-clockwise from world +x.

    Raises:
        BoardError: wrong image size, too few or collinear corners, a poor fit or a view too
            oblique to trust.
    """
    h, w = image.shape[:2]
    if (w, h) != (cam.width, cam.height):
        raise BoardError(f"image is {w}x{h} but camera {cam.id!r} is {cam.width}x{cam.height} in the site")
    return pose_from_corners(detect_corners(image, spec, cam), spec, cam, origin_xy, yaw)


def pose_from_corners(corners: Corners, spec: BoardSpec, cam: Camera, origin_xy: Sequence[float], yaw: float) -> PoseFit:
    """A camera's pose in the world from the board's corners found in its image.

    Args:
        corners: the corners, from ``detect_corners``.
        spec: the board.
        cam: the camera, with its intrinsics (its pose is not used).
        origin_xy: the board's origin on the floor, metres.
        yaw: the direction of the board's x axis, radians counter-clockwise from world +x.

    Raises:
        BoardError: too few or collinear corners, a poor fit or a view too oblique to trust.
    """
    _check_spread(corners, spec, MIN_CORNERS, "")
    pose = solve_board_pose(corners.object_points, corners.pixels, cam)
    if pose.reprojection_px > MAX_REPROJECTION_PX:
        raise BoardError(
            f"corners reproject with RMS {pose.reprojection_px:.2f} px, allowed <= {MAX_REPROJECTION_PX}: "
            "check the camera's intrinsics and the board's square and marker sizes"
        )
    w_m, h_m = spec.size_m
    centre_cam = pose.R @ np.array([w_m / 2, h_m / 2, 0.0]) + pose.t
    normal_cam = pose.R[:, 2]
    cos = abs(float(normal_cam @ centre_cam)) / float(np.linalg.norm(centre_cam))
    oblique = math.degrees(math.acos(min(1.0, cos)))
    if oblique > MAX_OBLIQUE_DEG:
        raise BoardError(
            f"the board is seen {oblique:.0f} deg from its normal, allowed <= {MAX_OBLIQUE_DEG:.0f}: "
            "lay it nearer the camera or raise the camera"
        )
    rotation, position = camera_pose_in_world(pose, origin_xy, yaw)
    return PoseFit(position, rotation, pose.reprojection_px, pose.corners, oblique)


def calibrate_intrinsics(images: Sequence[NDArray[np.uint8]], spec: BoardSpec, *, fix_k3: bool = True) -> IntrinsicsFit:
    """A camera's K and distortion from several views of the board.

    Args:
        images: grey or BGR uint8 images, all the same size, the board seen from varied angles
            and filling different parts of the image.
        spec: the board.
        fix_k3: keep k3 at zero: webcam lenses rarely need it and a handful of views leave it
            free to trade against the focal length.

    Raises:
        BoardError: images of different sizes, or fewer than 4 with enough corners.
    """
    if not images:
        raise BoardError("no images given")
    h, w = images[0].shape[:2]
    obj_pts, img_pts, skipped = [], [], []
    for i, image in enumerate(images):
        if image.shape[:2] != (h, w):
            raise BoardError(f"image {i} is {image.shape[1]}x{image.shape[0]}, the first is {w}x{h}: all must be one size")
        corners = detect_corners(image, spec)
        try:
            _check_spread(corners, spec, MIN_CORNERS, f"image {i}")
        except BoardError:
            skipped.append(i)
            continue
        obj_pts.append(corners.object_points.astype(np.float32).reshape(-1, 1, 3))
        img_pts.append(corners.pixels.astype(np.float32).reshape(-1, 1, 2))
    if len(obj_pts) < MIN_VIEWS:
        raise BoardError(
            f"{len(obj_pts)} of {len(images)} images show at least {MIN_CORNERS} corners, need at least {MIN_VIEWS} "
            "views of the board from varied angles"
        )
    flags = cv2.CALIB_FIX_K3 if fix_k3 else 0
    rms, K, dist, _, _ = cv2.calibrateCamera(obj_pts, img_pts, (w, h), None, None, flags=flags)
    return IntrinsicsFit(
        K=np.asarray(K, dtype=np.float64), dist=np.asarray(dist, dtype=np.float64).reshape(-1)[:5],
        rms_px=float(rms), image_size=(w, h), views=len(obj_pts), skipped=tuple(skipped),
    )


# --- rendering ----------------------------------------------------------------------------------

_PAPER: Final = 235.0  # white paper under room light, not a saturated 255
_INK: Final = 25.0


