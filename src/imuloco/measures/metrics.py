"""Reconstruction metrics: a ground-truth Motion against a reconstructed one on the same skeleton.

Every metric takes two motions of equal length and frame rate (``gt`` first) and returns a
float; the array-level helpers under them are pure functions that broadcast. Units: positions in
cm, speeds in cm/s, angles in degrees, jerk in m/s^3, D_pv in m^2 (positions in metres).

Body halves (:func:`body_halves`): the lower body is both hip joints and every joint below
them; the upper body is every other joint but the root (pelvis). This covers all joints of any
skeleton, where the canonical :data:`imuloco.core.bodymap.LOWER_PARTS` would skip unmapped
ones (clavicles, fingers).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from imuloco.core.bodymap import LOWER_PARTS, PART_GROUPS, PARTS, UPPER_PARTS
from imuloco.core.motion import Motion
from imuloco.core.skeleton import Skeleton
from imuloco.errors import InputError
from imuloco.io.motionfile import read_motion
from imuloco.ops.heading import heading_from_hips, to_heading_frame
from imuloco.ops.rotations import about_y, geodesic, qinv, qmul, qrot
from imuloco.phases import foot_contacts

CM = 100.0
WINDOW_S = 2.0  # root-trajectory windows (speed and path errors), seconds


def check_pair(gt: Motion, rec: Motion) -> None:
    """Raise ValueError unless two motions share a skeleton, a frame count and a frame rate."""
    a, b = gt.skeleton, rec.skeleton
    if a.names != b.names or not np.array_equal(a.parents, b.parents):
        raise ValueError(f"motions {gt.name!r} and {rec.name!r} have different skeletons "
                         f"({a.num_joints} vs {b.num_joints} joints or other names/parents)")
    if gt.num_frames != rec.num_frames:
        raise ValueError(f"motions {gt.name!r} and {rec.name!r} differ in length: "
                         f"{gt.num_frames} vs {rec.num_frames} frames")
    if abs(gt.fps - rec.fps) > 1e-6 * gt.fps:
        raise ValueError(f"motions differ in frame rate: {gt.fps} vs {rec.fps} fps")


# ---- poses ------------------------------------------------------------------------------------
def heading_of(motion: Motion, positions: np.ndarray | None = None) -> np.ndarray:
    """Heading angle per frame (T,) from the hip line (:func:`imuloco.ops.heading`)."""
    pos = motion.positions() if positions is None else positions
    sk = motion.skeleton
    return heading_from_hips(pos[:, sk.part("left_hip")], pos[:, sk.part("right_hip")])


def local_positions(motion: Motion) -> np.ndarray:
    """Joint positions relative to the pelvis (root joint) in the heading frame, (T, J, 3) m.

    The heading frame has its origin at the pelvis and the pelvis's yaw (from the hip line)
    removed, so these positions do not change when the whole motion is moved or turned
    about the vertical.
    """
    pos = motion.positions()
    return to_heading_frame(pos, pos[:, 0], heading_of(motion, pos))


def joint_errors(gt: Motion, rec: Motion) -> np.ndarray:
    """Per frame and joint distance (T, J), metres, between :func:`local_positions`."""
    check_pair(gt, rec)
    return np.linalg.norm(local_positions(gt) - local_positions(rec), axis=-1)


def body_halves(skeleton: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    """Joint indices of the upper and lower body (see the module docstring); never the root."""
    lower = np.zeros(skeleton.num_joints, dtype=bool)
    for side in ("left", "right"):
        lower[skeleton.part(f"{side}_hip")] = True
    for j in range(1, skeleton.num_joints):  # parents precede children
        lower[j] |= lower[skeleton.parents[j]]
    upper = ~lower
    upper[0] = lower[0] = False
    return np.flatnonzero(upper), np.flatnonzero(lower)


def _joints(skeleton: Skeleton, joints: str | np.ndarray | None) -> np.ndarray:
    if joints is None or (isinstance(joints, str) and joints == "all"):
        return np.arange(1, skeleton.num_joints)
    if isinstance(joints, str):
        upper, lower = body_halves(skeleton)
        return {"upper": upper, "lower": lower}[joints]
    return np.asarray(joints)


def mpjpe(gt: Motion, rec: Motion, joints: str | np.ndarray | None = None) -> float:
    """Mean per-joint position error, cm.

    Mean over frames and joints of the Euclidean distance between joint positions relative to
    the pelvis in the heading frame (:func:`local_positions`), the measure of Eom et al. 2014
    (sec. 7, "joint positions relative to the root") and Mousas 2017 (Table 3). ``joints``:
    ``None``/``"all"`` (every joint but the root), ``"upper"``, ``"lower"`` or indices.
    """
    return float(joint_errors(gt, rec)[:, _joints(gt.skeleton, joints)].mean() * CM)


def rmse(gt: Motion, rec: Motion, joints: str | np.ndarray | None = None) -> float:
    """Root-mean-square joint position error, cm, as Eom et al. 2014 sec. 7 (Fig. 9, Table 1).

    Per frame, the square root of the mean over joints of the squared distances between
    :func:`local_positions`; then the mean over frames ("average RMSE ... in every frame").
    """
    return float(rmse_per_frame(gt, rec, joints).mean())


def rmse_per_frame(gt: Motion, rec: Motion, joints: str | np.ndarray | None = None
                   ) -> np.ndarray:
    """The per-frame RMSE (T,) of :func:`rmse`, cm: the curve of Eom et al. 2014 Fig. 9."""
    err = joint_errors(gt, rec)[:, _joints(gt.skeleton, joints)]
    return np.sqrt((err**2).mean(axis=1)) * CM


def angle_error(gt: Motion, rec: Motion) -> float:
    """Joint angle error D_E, degrees (Tautges et al. 2008 sec. 6, after Chai & Hodgins 2005).

    Mean over frames and all joints of the geodesic angle between the local rotations. The
    root's rotation is taken relative to its heading frame (its yaw from the hip line
    removed), so that the measure, like :func:`mpjpe`, ignores where the figure faces.
    """
    check_pair(gt, rec)
    a, b = _heading_free(gt), _heading_free(rec)
    return float(np.degrees(geodesic(a, b)).mean())


def _heading_free(motion: Motion) -> np.ndarray:
    rot = motion.rotations.copy()
    rot[:, 0] = qmul(qinv(about_y(heading_of(motion))), rot[:, 0])
    return rot


# ---- D_pv ---------------------------------------------------------------------------------
def dpv_positions(p1: np.ndarray, p2: np.ndarray, parents: np.ndarray,
                  joints: np.ndarray | None = None) -> float:
    """D_pv of Tautges et al. 2008 sec. 3.1, eq. (5)-(16), from joint positions.

    For every joint j with two or more children and every ordered pair of distinct children
    (a, b), the cross product ``c(f) = v_{j->a}(f) x v_{j->b}(f)`` (eq. 5) of each motion and its
    time derivative give ``D(f) = C(f) + Cdot(f)`` (eq. 11) with ``C = |c1 - c2|`` (eq. 12) and
    ``Cdot = dt |c1' - c2'|`` (eq. 13), ``dt = |v_{j->a}| |v_{j->b}| / (|c1'| + |c2'|)``
    (eq. 14, bone lengths of motion 1; ``Cdot = 0`` where both derivatives vanish). Then
    ``D_pv = sqrt(sum_f sum_j sum_{a != b} D(f)^2)`` (eq. 15-16): a sum over frames, not a
    mean, so it grows with the clip's length. Joints with fewer than two children contribute
    nothing, as in the paper (on the shared skeleton: the hips and the chest). Computed in the
    global frame: invariant under translation, not under rotation (as the paper notes). The
    derivative is ``np.gradient`` (central differences); its time unit cancels in ``Cdot``.

    Parameters
    ----------
    p1, p2 : ndarray, shape (T, J, 3), world joint positions (metres, so D_pv is in m^2).
    parents : ndarray, shape (J,), int.
    joints : the joints j to sum over (default: all).

    Returns
    -------
    float
    """
    p1, p2 = np.asarray(p1, dtype=np.float64), np.asarray(p2, dtype=np.float64)
    if p1.shape != p2.shape or p1.ndim != 3:
        raise ValueError(f"dpv: positions must both be (T, J, 3), got {p1.shape}, {p2.shape}")
    parents = np.asarray(parents)
    js = range(len(parents)) if joints is None else joints
    pairs = [(j, a, b) for j in js for a in np.flatnonzero(parents == j)
             for b in np.flatnonzero(parents == j) if a != b]
    if not pairs:
        return 0.0
    j, a, b = (np.array(x) for x in zip(*pairs))
    va1, vb1 = p1[:, a] - p1[:, j], p1[:, b] - p1[:, j]
    c1, c2 = np.cross(va1, vb1), np.cross(p2[:, a] - p2[:, j], p2[:, b] - p2[:, j])
    if len(p1) > 1:
        d1, d2 = np.gradient(c1, axis=0), np.gradient(c2, axis=0)
    else:
        d1 = d2 = np.zeros_like(c1)
    big_c = np.linalg.norm(c1 - c2, axis=-1)
    denom = np.linalg.norm(d1, axis=-1) + np.linalg.norm(d2, axis=-1)
    num = np.linalg.norm(va1, axis=-1) * np.linalg.norm(vb1, axis=-1)
    dt = np.divide(num, denom, out=np.zeros_like(denom), where=denom > 0)
    d = big_c + dt * np.linalg.norm(d1 - d2, axis=-1)
    return float(np.sqrt((d**2).sum()))


def dpv(gt: Motion, rec: Motion, joints: np.ndarray | None = None) -> float:
    """D_pv (Tautges et al. 2008 sec. 3.1) of two motions; see :func:`dpv_positions`."""
    check_pair(gt, rec)
    return dpv_positions(gt.positions(), rec.positions(), gt.skeleton.parents, joints)


# ---- smoothness and contacts --------------------------------------------------------------
def jerk(positions: np.ndarray, fps: float) -> np.ndarray:
    """Jerk magnitude, shape (T-3, ...), of positions (T, ..., 3) in metres: third finite
    difference times fps^3, m/s^3."""
    return np.linalg.norm(np.diff(positions, n=3, axis=0), axis=-1) * fps**3


def jitter(motion: Motion) -> float:
    """Mean jerk of the world joint positions (all joints), m/s^3: the smoothness measure of
    motion-synthesis work (e.g. Yi et al. 2021's "jitter"); 0 for constant velocity.
    Clips shorter than 4 frames give 0."""
    if motion.num_frames < 4:
        return 0.0
    return float(jerk(motion.positions(), motion.fps).mean())


def gt_contacts(gt: Motion) -> dict[str, np.ndarray]:
    """Heel and toe contacts (T,) of the ground truth, from :func:`imuloco.phases.foot_contacts`
    (height above the clip's floor and speed, Eom et al. 2014 sec. 6.2)."""
    return foot_contacts(gt)


def foot_skate(gt: Motion, rec: Motion, contacts: dict[str, np.ndarray] | None = None) -> float:
    """Foot skating, cm/s: mean horizontal speed of the reconstructed feet while the ground
    truth's feet are in contact.

    The heel (ankle joint) counts while the ground-truth heel is down, the toe joint while the
    toe is down (contacts from :func:`gt_contacts`); the speed between frames t and t+1
    counts when both are in contact. Pooled over both feet, heel and toe samples alike.
    ``nan`` when the ground truth has no contact.
    """
    check_pair(gt, rec)
    contacts = gt_contacts(gt) if contacts is None else contacts
    return skate(rec.part_positions(list(FOOT_PARTS)), contacts, rec.fps)


FOOT_PARTS = ("left_ankle", "left_toe", "right_ankle", "right_toe")


def skate(feet: np.ndarray, contacts: dict[str, np.ndarray], fps: float) -> float:
    """:func:`foot_skate` of foot positions (T, 4, 3) in :data:`FOOT_PARTS` order, metres."""
    speeds = []
    for k, part in enumerate(FOOT_PARTS):
        side, kind = part.split("_")
        c = np.asarray(contacts[f"{side}_{'heel' if kind == 'ankle' else 'toe'}"], dtype=bool)
        both = c[:-1] & c[1:]
        step = np.linalg.norm(np.diff(feet[:, k][:, [0, 2]], axis=0), axis=-1) * fps
        speeds.append(step[both])
    s = np.concatenate(speeds)
    return float(s.mean() * CM) if s.size else float("nan")


# ---- root trajectory -----------------------------------------------------------------------
def time_windows(num_frames: int, fps: float, window_s: float = WINDOW_S
                 ) -> list[tuple[int, int]]:
    """Consecutive non-overlapping windows ``(start, stop)`` of ``window_s`` seconds (frames
    ``start..stop`` inclusive span ``window_s``); a clip shorter than one window is one window
    of its whole length; frames after the last full window are left out."""
    w = max(round(window_s * fps), 1)
    if num_frames <= w:
        return [(0, num_frames - 1)]
    return [(s, s + w) for s in range(0, num_frames - w, w)]


def root_speed_error(gt: Motion, rec: Motion, window_s: float = WINDOW_S) -> float:
    """Root speed error, cm/s: mean over :func:`time_windows` of the absolute difference
    between the two motions' mean horizontal root speeds (horizontal distance from the window's
    first to its last frame over its duration; steps' sway cancels). Our measure for the
    issue's "root trajectory speed error"; no paper defines one."""
    check_pair(gt, rec)
    return speed_error(gt.root, rec.root, gt.fps, window_s)


def speed_error(a: np.ndarray, b: np.ndarray, fps: float, window_s: float = WINDOW_S) -> float:
    """:func:`root_speed_error` of two root paths (T, 3), metres."""
    errs = []
    for s, e in time_windows(len(a), fps, window_s):
        if e == s:
            continue
        dur = (e - s) / fps
        v = [np.linalg.norm(m[e, [0, 2]] - m[s, [0, 2]]) / dur for m in (a, b)]
        errs.append(abs(v[0] - v[1]))
    return float(np.mean(errs) * CM) if errs else 0.0


def align_heading(rec: Motion, gt: Motion, frame: int = 0) -> Motion:
    """``rec`` turned about the vertical and moved horizontally so that at ``frame`` its root
    stands where the ground truth's does and faces the same heading (height unchanged)."""
    d = heading_of(gt)[frame] - heading_of(rec)[frame]
    q = about_y(np.asarray(d))
    rot = rec.rotations.copy()
    rot[:, 0] = qmul(q, rot[:, 0])
    root = qrot(q, rec.root - rec.root[frame]) + rec.root[frame]
    root[:, [0, 2]] += gt.root[frame, [0, 2]] - rec.root[frame, [0, 2]]
    return Motion(rec.skeleton, rot, root, rec.fps, rec.name)


def path_error(gt: Motion, rec: Motion, window_s: float = WINDOW_S) -> float:
    """Heading-aligned path error, cm: for each of :func:`time_windows`, the reconstruction is
    aligned to the ground truth's root position and heading at the window's first frame
    (:func:`align_heading`), then the horizontal root distance is averaged over the window's
    frames; the mean over windows. It measures drift within ``window_s`` seconds, not the
    accumulated drift of a whole clip. Our measure for the issue; no paper defines one."""
    check_pair(gt, rec)
    return path_error_of(gt.root, heading_of(gt), rec.root, heading_of(rec), gt.fps, window_s)


def path_error_of(a: np.ndarray, heading_a: np.ndarray, b: np.ndarray, heading_b: np.ndarray,
                  fps: float, window_s: float = WINDOW_S) -> float:
    """:func:`path_error` of root paths (T, 3), metres, with their headings (T,), radians."""
    errs = []
    for s, e in time_windows(len(a), fps, window_s):
        q = about_y(np.asarray(heading_a[s] - heading_b[s]))
        path = qrot(q, b[s:e + 1] - b[s]) + a[s]
        errs.append(np.linalg.norm((path - a[s:e + 1])[:, [0, 2]], axis=-1).mean())
    return float(np.mean(errs) * CM)


# ---- everything --------------------------------------------------------------------------------
# cross-dataset only: part errors against the ground truth retargeted onto the
# reconstruction's skeleton (:func:`evaluate_parts`; :func:`evaluate` has no such keys)
RETARGETED_KEYS = ("mpjpe_retargeted_cm", "upper_retargeted_cm", "lower_retargeted_cm")
# mean position error of each group of :data:`imuloco.core.bodymap.PART_GROUPS`' canonical
# parts (heading frame at the pelvis, cm): comparable across skeletons and against the mean pose
GROUP_KEYS = tuple(f"{g}_cm" for g in PART_GROUPS)
# cross-dataset only: the same groups against the ground truth retargeted (as RETARGETED_KEYS)
GROUP_RETARGETED_KEYS = tuple(f"{g}_retargeted_cm" for g in PART_GROUPS)
METRIC_KEYS = ("mpjpe_cm", "rmse_cm", "upper_cm", "lower_cm", "upper_rmse_cm",
               "lower_rmse_cm", "angle_deg", "dpv", "jitter",
               "jitter_gt", "foot_skate_cm_s", "foot_skate_gt_cm_s", "root_speed_err_cm_s",
               "path_err_cm", *RETARGETED_KEYS, *GROUP_KEYS, *GROUP_RETARGETED_KEYS)


def group_errors(err: np.ndarray, index: dict[str, int]) -> dict[str, float]:
    """:data:`GROUP_KEYS` from per-frame errors ``err`` (T, N), metres, whose column
    ``index[part]`` is a canonical part's (a part absent from ``index`` is left out)."""
    out = {}
    for group, parts in PART_GROUPS.items():
        cols = [index[p] for p in parts if p in index]
        out[f"{group}_cm"] = float(err[:, cols].mean() * CM) if cols else None
    return out


def evaluate(gt: Motion, rec: Motion) -> dict[str, float]:
    """Every metric of this module for one pair, keyed as in :data:`METRIC_KEYS`.

    ``upper_cm``/``lower_cm`` are :func:`mpjpe` of the body halves, ``upper_rmse_cm``/
    ``lower_rmse_cm`` their :func:`rmse` (the form of Eom et al. 2014 Table 1).
    ``jitter_gt`` and ``foot_skate_gt_cm_s`` measure the ground truth itself (the floor that
    capture noise and the contact detector leave).
    """
    check_pair(gt, rec)
    err = joint_errors(gt, rec)
    upper, lower = body_halves(gt.skeleton)
    body = np.arange(1, gt.skeleton.num_joints)
    contacts = gt_contacts(gt)
    mapped = gt.skeleton.body_map or {}
    parts = {p: gt.skeleton.part(p) for g in PART_GROUPS.values() for p in g if p in mapped}
    return {
        "mpjpe_cm": float(err[:, body].mean() * CM),
        "rmse_cm": float(np.sqrt((err[:, body] ** 2).mean(axis=1)).mean() * CM),
        "upper_cm": float(err[:, upper].mean() * CM),
        "lower_cm": float(err[:, lower].mean() * CM),
        "upper_rmse_cm": float(np.sqrt((err[:, upper] ** 2).mean(axis=1)).mean() * CM),
        "lower_rmse_cm": float(np.sqrt((err[:, lower] ** 2).mean(axis=1)).mean() * CM),
        "angle_deg": angle_error(gt, rec),
        "dpv": dpv(gt, rec),
        "jitter": jitter(rec),
        "jitter_gt": jitter(gt),
        "foot_skate_cm_s": foot_skate(gt, rec, contacts),
        "foot_skate_gt_cm_s": foot_skate(gt, gt, contacts),
        "root_speed_err_cm_s": root_speed_error(gt, rec),
        "path_err_cm": path_error(gt, rec),
        **group_errors(err, parts),
    }


def evaluate_files(ground_truth: str | Path, reconstructed: str | Path,
                   offset_tol: float = 1e-3) -> tuple[dict[str, float], str]:
    """:func:`evaluate` of two motion files; returns the metrics and a note ("" or what was cut).

    The skeletons must have the same joint names, parents and offsets (within ``offset_tol``
    metres) and the same frame rate; the longer motion is cut to the shorter's length.
    """
    gt, rec = read_motion(ground_truth), read_motion(reconstructed)
    for path, motion in ((ground_truth, gt), (reconstructed, rec)):
        if motion.num_frames < 2:  # its gait and velocities need two
            raise InputError(f"{path}: {motion.num_frames} frame; evaluating needs at least 2")
    a, b = gt.skeleton, rec.skeleton
    if a.names != b.names or not np.array_equal(a.parents, b.parents):
        n = min(len(a.names), len(b.names))
        k = next((i for i, (x, y) in enumerate(zip(b.names, a.names)) if x != y), n)
        first = (f"joint {k} is {b.names[k]!r} against {a.names[k]!r}" if k < n else
                 f"the first {n} joints are the same" if a.names != b.names else
                 "the joints' parents differ")
        raise InputError(f"{reconstructed}: its skeleton differs from {ground_truth}'s "
                         f"({len(b.names)} joints against {len(a.names)}; {first})")
    worst = float(np.abs(a.offsets - b.offsets).max())
    if worst > offset_tol:
        j = int(np.abs(a.offsets - b.offsets).max(axis=1).argmax())
        raise InputError(f"{reconstructed}: bone offsets differ from {ground_truth}'s "
                         f"(joint {a.names[j]!r} by {worst * CM:.2f} cm; a reconstruction on a "
                         "T-pose rest compares with `reconstruct --rig model`)")
    if abs(gt.fps - rec.fps) > 1e-3 * gt.fps:
        raise InputError(f"{reconstructed}: {rec.fps:g} fps, but {ground_truth} has "
                         f"{gt.fps:g} fps; resample one first")
    n = min(gt.num_frames, rec.num_frames)
    note = ""
    if gt.num_frames != rec.num_frames:
        note = (f"lengths differ ({gt.num_frames} vs {rec.num_frames} frames): "
                f"evaluating the first {n}")
    rec = Motion(a, rec.rotations[:n], rec.root[:n], rec.fps, rec.name)
    return evaluate(gt.slice(0, n), rec), note


def part_errors(gt: Motion, rec: Motion) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                  np.ndarray, np.ndarray]:
    """Per frame and canonical body part distance (T, P), metres, of a reconstruction on
    another skeleton (see :func:`evaluate_parts` for the scaling and alignment), with the
    ground truth's and the aligned reconstruction's part positions (T, P, 3) and headings
    (T,)."""
    if gt.num_frames != rec.num_frames or abs(gt.fps - rec.fps) > 1e-6 * gt.fps:
        raise ValueError(f"motions {gt.name!r} and {rec.name!r} differ in length or frame "
                         f"rate: {gt.num_frames} frames at {gt.fps:g} fps vs "
                         f"{rec.num_frames} at {rec.fps:g}")
    parts = list(PARTS)
    k = {p: i for i, p in enumerate(parts)}
    pg = gt.part_positions(parts)
    pr = rec.part_positions(parts)
    start = pr[0, k["pelvis"]] * np.array([1.0, 0.0, 1.0])  # heights scale from the floor
    pr = (pr - start) * (gt.skeleton.leg_length() / rec.skeleton.leg_length())
    hg = heading_from_hips(pg[:, k["left_hip"]], pg[:, k["right_hip"]])
    hr = heading_from_hips(pr[:, k["left_hip"]], pr[:, k["right_hip"]])
    pr = qrot(about_y(np.asarray(hg[0] - hr[0])), pr)
    pr[..., [0, 2]] += pg[0, k["pelvis"], [0, 2]]
    hr = hr + (hg[0] - hr[0])
    err = np.linalg.norm(to_heading_frame(pg, pg[:, k["pelvis"]], hg)
                         - to_heading_frame(pr, pr[:, k["pelvis"]], hr), axis=-1)
    return err, pg, pr, hg, hr


def evaluate_parts(gt: Motion, rec: Motion, retargeted: Motion | None = None
                   ) -> dict[str, float | None]:
    """:func:`evaluate`'s metrics for a reconstruction on another skeleton than its ground
    truth's (the ``cross-dataset`` protocol), on the canonical body parts only.

    The reconstruction's part positions are scaled by the ratio of leg lengths (ground truth
    over reconstruction) about its first pelvis position, then turned and moved so that at
    frame 0 its pelvis stands over the ground truth's and faces its heading. Position errors
    are in the heading frame at the pelvis (parts but the pelvis; upper and lower halves as
    :data:`imuloco.core.bodymap.UPPER_PARTS` / ``LOWER_PARTS``), jitter is over the parts,
    the root is the pelvis. ``angle_deg`` and ``dpv`` compare joint by joint and are None.

    Bodies of other proportions put a floor under these errors: the ground truth itself,
    retargeted onto the reconstruction's skeleton, is not at zero. ``retargeted`` (that
    motion) adds :data:`RETARGETED_KEYS` and :data:`GROUP_RETARGETED_KEYS`, the same part
    errors against it, whose floor is zero: the reconstruction's own error, without the
    rigs' differences.
    """
    return evaluate_parts_curves(gt, rec, retargeted)[0]


def evaluate_parts_curves(gt: Motion, rec: Motion, retargeted: Motion | None = None
                          ) -> tuple[dict[str, float | None], np.ndarray, np.ndarray | None]:
    """:func:`evaluate_parts`, with the per-frame rms part error (T,), metres, over the parts
    but the pelvis, against ``gt`` and against ``retargeted`` (None without it): the curves
    the metrics average, each pair's part errors computed once."""
    parts = list(PARTS)
    k = {p: i for i, p in enumerate(parts)}
    err, pg, pr, hg, hr = part_errors(gt, rec)
    body = [k[p] for p in parts if p != "pelvis"]
    upper, lower = [k[p] for p in UPPER_PARTS], [k[p] for p in LOWER_PARTS]
    contacts = gt_contacts(gt)
    feet = [k[p] for p in FOOT_PARTS]

    def curve(e: np.ndarray, idx: list[int]) -> np.ndarray:
        return np.sqrt((e[:, idx] ** 2).mean(axis=1))

    def means(e: np.ndarray) -> tuple[float, float, float]:
        return tuple(float(e[:, i].mean() * CM) for i in (body, upper, lower))

    short = gt.num_frames < 4
    actual, actual_retargeted = curve(err, body), None
    against = dict.fromkeys((*RETARGETED_KEYS, *GROUP_RETARGETED_KEYS))
    if retargeted is not None:
        err_retargeted = part_errors(retargeted, rec)[0]
        against = dict(zip(RETARGETED_KEYS, means(err_retargeted)))
        against.update({f"{g[:-3]}_retargeted_cm": v
                        for g, v in group_errors(err_retargeted, k).items()})
        actual_retargeted = curve(err_retargeted, body)
    mpjpe_cm, upper_cm, lower_cm = means(err)
    values = {
        "mpjpe_cm": mpjpe_cm, "rmse_cm": float(actual.mean() * CM),
        "upper_cm": upper_cm, "lower_cm": lower_cm,
        "upper_rmse_cm": float(curve(err, upper).mean() * CM),
        "lower_rmse_cm": float(curve(err, lower).mean() * CM),
        "angle_deg": None, "dpv": None,
        "jitter": 0.0 if short else float(jerk(pr, gt.fps).mean()),
        "jitter_gt": 0.0 if short else float(jerk(pg, gt.fps).mean()),
        "foot_skate_cm_s": skate(pr[:, feet], contacts, gt.fps),
        "foot_skate_gt_cm_s": skate(pg[:, feet], contacts, gt.fps),
        "root_speed_err_cm_s": speed_error(pg[:, k["pelvis"]], pr[:, k["pelvis"]], gt.fps),
        "path_err_cm": path_error_of(pg[:, k["pelvis"]], hg, pr[:, k["pelvis"]], hr, gt.fps),
        **against,
        **group_errors(err, k),
    }
    return values, actual, actual_retargeted
