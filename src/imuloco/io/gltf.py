"""glTF 2.0 writing (``.glb`` binary, ``.gltf`` JSON with the data embedded): a skinned
stick figure and its animation, which Blender, three.js, Godot and Unity (glTFast) import.

- The skeleton is a skin: one node per joint (its rest offset as translation, no rest
  rotation), plus an ``_end`` node under each leaf joint (head top, hand and toe tips, as
  Mixamo's ``HeadTop_End``), the root node standing with its feet on the floor; the bind pose is
  the rest pose, so each inverse bind matrix is a translation. Write a motion on a T-pose rest
  (:func:`imuloco.core.rigs.apply_rig`) for a T-pose bind.
- The animation samples every joint's local rotation and the root's translation at each frame
  (``LINEAR``; the sampler's times are ``frame / fps``; glTF has no frame rate of its own, so
  ``fps`` is also in the animation's ``extras``).
- A mesh makes it visible: an octahedral bone (Blender's bone shape) from each joint to each
  child and end, skinned rigidly to the joint.
- Units are metres, Y up, the figure facing +Z (glTF's own conventions, and imuloco's).

The JSON, accessors and binary chunk are laid out by pygltflib (the ``[gltf]`` extra);
the arrays are packed here with numpy.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from imuloco.core.motion import Motion
from imuloco.errors import MissingExtraError
from imuloco.io.atomic import atomic_path, check_output
from imuloco.io.bvh import end_sites
from imuloco.ops.kinematics import fk
from imuloco.ops.rotations import IDENTITY, continuous, normalize

SUFFIXES = (".glb", ".gltf")
_FLOAT, _USHORT, _UINT = 5126, 5123, 5125  # glTF component types
_ARRAY, _ELEMENTS = 34962, 34963  # bufferView targets
BONE_RING = 0.2  # where an octahedral bone is widest, as a fraction of its length
BONE_RADIUS = 0.08  # its radius there, as a fraction of its length


def pygltflib_module():
    """The pygltflib module, or :class:`MissingExtraError` naming the ``[gltf]`` extra."""
    try:
        import pygltflib  # optional extra [gltf]: imported when a glTF is written
    except ImportError:
        raise MissingExtraError("writing glTF", "pygltflib", "gltf") from None
    return pygltflib


def rest_ends(motion: Motion, height: float | None = None) -> dict[int, np.ndarray]:
    """Each leaf joint's end vector (3,), metres, in its frame at rest: the BVH writer's End
    Site with the toes laid flat along the floor and, when the body ``height`` is given, the
    head's top that high above the rest figure's feet (:func:`imuloco.io.bvh.end_sites`)."""
    sk = motion.skeleton
    return {j: e for j, e in end_sites(sk, height, flat_toes=True).items()
            if not sk.children(j)}


def _octahedron(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (24, 3) and flat normals (24, 3) of an octahedral bone from ``a`` to ``b``:
    8 triangles, 3 vertices each, wound counter-clockwise seen from outside."""
    axis = b - a
    length = np.linalg.norm(axis)
    u = axis / length
    side = np.cross(u, [0.0, 1.0, 0.0] if abs(u[1]) < 0.9 else [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    other = np.cross(u, side)
    r = BONE_RADIUS * length
    centre = a + BONE_RING * axis
    ring = [centre + r * v for v in (side, other, -side, -other)]
    tris = []
    for k in range(4):
        p, q = ring[k], ring[(k + 1) % 4]
        tris += [(a, q, p), (b, p, q)]
    verts = np.array([v for t in tris for v in t])
    normals = []
    for t in tris:
        n = np.cross(t[1] - t[0], t[2] - t[0])
        normals += [n / np.linalg.norm(n)] * 3
    return verts, np.array(normals)


def _bones_mesh(motion: Motion, bind: np.ndarray, tips: dict[int, np.ndarray]
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices (V, 3), normals (V, 3) and owning joints (V,) of an octahedral bone from each
    joint (bind positions (J, 3)) to each child and from each leaf to its tip (3,)."""
    sk = motion.skeleton
    bones = [(int(sk.parents[c]), bind[int(sk.parents[c])], bind[c])
             for c in range(1, sk.num_joints) if np.linalg.norm(sk.offsets[c]) > 1e-6]
    bones += [(j, bind[j], tip) for j, tip in tips.items()]
    shapes = [_octahedron(a, b) for _, a, b in bones]
    return (np.concatenate([v for v, _ in shapes]), np.concatenate([m for _, m in shapes]),
            np.repeat([j for j, _, _ in bones], 24))


def write_gltf(motion: Motion, path: str | Path, overwrite: bool = False, mesh: bool = True,
               height: float | None = None) -> Path:
    """Write ``motion`` as glTF 2.0: ``.glb`` (binary) or ``.gltf`` (JSON, data embedded).

    ``mesh``: add the skinned octahedral bones; ``height``: the body height the figure's head
    reaches (:func:`rest_ends`). Refuses to replace an existing file unless ``overwrite``;
    the file appears (atomically) only when complete. Returns the path.
    """
    path = Path(path)
    if path.suffix.lower() not in SUFFIXES:
        raise ValueError(f"{path}: expected a .glb or .gltf file")
    check_output(path, overwrite)
    g = pygltflib_module()
    sk = motion.skeleton
    n = sk.num_joints
    ends = rest_ends(motion, height)
    leaves = sorted(ends)
    # the rest (bind) pose: world positions of the joints and ends, standing on the floor
    _, rest = fk(np.broadcast_to(IDENTITY, (n, 4)), np.zeros(3), sk.offsets, sk.parents)
    tips = np.array([rest[j] + ends[j] for j in leaves]).reshape(-1, 3)
    lift = -min(rest[:, 1].min(), tips[:, 1].min(initial=np.inf))
    rest, tips = rest + [0.0, lift, 0.0], tips + [0.0, lift, 0.0]
    bind = np.concatenate([rest, tips])  # (J + leaves, 3): every skin joint
    offsets = sk.offsets.copy()
    offsets[0] = rest[0]

    blob = bytearray()
    views: list = []
    accessors: list = []

    def add(data: np.ndarray, kind: str, ctype: int = _FLOAT, target: int | None = None,
            bounds: bool = False) -> int:
        """Append ``data`` to the buffer as a new bufferView and accessor; its index."""
        raw = np.ascontiguousarray(data, dtype={_FLOAT: "<f4", _USHORT: "<u2",
                                                _UINT: "<u4"}[ctype]).tobytes()
        blob.extend(b"\0" * (-len(blob) % 4))
        views.append(g.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(raw),
                                  target=target))
        blob.extend(raw)
        flat = np.asarray(data).reshape(len(data), -1)
        accessors.append(g.Accessor(
            bufferView=len(views) - 1, componentType=ctype, count=len(data), type=kind,
            min=flat.min(axis=0).astype(np.float32).tolist() if bounds else None,
            max=flat.max(axis=0).astype(np.float32).tolist() if bounds else None))
        return len(accessors) - 1

    nodes = []
    for j in range(n):
        kids = sk.children(j) + ([n + leaves.index(j)] if j in ends else [])
        nodes.append(g.Node(name=sk.names[j], translation=offsets[j].tolist(),
                            children=kids or None))
    for j in leaves:
        nodes.append(g.Node(name=f"{sk.names[j]}_end", translation=ends[j].tolist()))
    joints = list(range(len(nodes)))
    inverse_bind = np.tile(np.eye(4), (len(bind), 1, 1))
    inverse_bind[:, :3, 3] = -bind
    # glTF matrices are column-major: each matrix's transpose, flattened row by row
    skin = g.Skin(name="imuloco", joints=joints, skeleton=0,
                  inverseBindMatrices=add(inverse_bind.transpose(0, 2, 1).reshape(-1, 16),
                                          "MAT4"))
    scene_nodes = [0]
    meshes = []
    materials = []
    if mesh:
        verts, normals, owner = _bones_mesh(motion, bind, dict(zip(leaves, tips)))
        joint_ids = np.zeros((len(verts), 4), dtype=np.uint16)
        joint_ids[:, 0] = owner
        weights = np.zeros((len(verts), 4))
        weights[:, 0] = 1.0
        prim = g.Primitive(
            attributes=g.Attributes(
                POSITION=add(verts, "VEC3", target=_ARRAY, bounds=True),
                NORMAL=add(normals, "VEC3", target=_ARRAY),
                JOINTS_0=add(joint_ids, "VEC4", _USHORT, _ARRAY),
                WEIGHTS_0=add(weights, "VEC4", target=_ARRAY)),
            indices=add(np.arange(len(verts)), "SCALAR", _UINT, _ELEMENTS), material=0)
        meshes.append(g.Mesh(name="bones", primitives=[prim]))
        materials.append(g.Material(name="bones", pbrMetallicRoughness=g.PbrMetallicRoughness(
            baseColorFactor=[0.85, 0.55, 0.2, 1.0], metallicFactor=0.0,
            roughnessFactor=0.7)))
        nodes.append(g.Node(name="figure", mesh=0, skin=0))
        scene_nodes.append(len(nodes) - 1)

    times = add(motion.times, "SCALAR", bounds=True)
    samplers = [g.AnimationSampler(input=times, output=add(motion.root, "VEC3"),
                                   interpolation="LINEAR")]
    channels = [g.AnimationChannel(sampler=0, target=g.AnimationChannelTarget(
        node=0, path="translation"))]
    rotations = continuous(normalize(motion.rotations))  # no sign flips between frames
    for j in range(n):
        samplers.append(g.AnimationSampler(input=times, output=add(rotations[:, j], "VEC4"),
                                           interpolation="LINEAR"))
        channels.append(g.AnimationChannel(sampler=len(samplers) - 1,
                                           target=g.AnimationChannelTarget(node=j,
                                                                           path="rotation")))
    gltf = g.GLTF2(
        asset=g.Asset(generator="imuloco", version="2.0"), scene=0,
        scenes=[g.Scene(name=motion.name or "imuloco", nodes=scene_nodes)], nodes=nodes,
        skins=[skin], meshes=meshes, materials=materials, accessors=accessors,
        bufferViews=views, buffers=[g.Buffer(byteLength=len(blob))],
        animations=[g.Animation(name=motion.name or "motion", samplers=samplers,
                                channels=channels, extras={"fps": motion.fps})])
    gltf.set_binary_blob(bytes(blob))
    with atomic_path(path) as tmp:
        if path.suffix.lower() == ".glb":
            gltf.save_binary(str(tmp))
        else:
            gltf.convert_buffers(g.BufferFormat.DATAURI)
            gltf.save_json(str(tmp))
    return path
