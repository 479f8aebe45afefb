"""Match result rocks to true rocks by the area of result surface lying on each true surface.

Every result face (cut into pieces no longer than the sampling length) takes the label of the
nearest true surface (the truth scene mesh, hidden rock parts included), unless that surface is
further than a distance gate. Summing areas gives an overlap matrix between result rocks and true
labels, measured on the result's surface:
``overlap[r, t]`` is the area of result rock ``r`` lying on true rock ``t``. The reconstructed
surface of true rock ``t`` is every result face labelled ``t``, whatever result rock it belongs to
(unassigned faces included), so a rock left half unassigned scores half.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
import open3d as o3d
from scipy.optimize import linear_sum_assignment

from ...meshio import LabelledMesh
from ...progress import progress

__all__ = [
    'GROUND',
    'MAX_PIECES',
    'MAX_SPLIT_LEVELS',
    'OFF_SURFACE',
    'Detection',
    'LabelTransfer',
    'MatchOptions',
    'RockMatching',
    'match_rocks',
    'split_faces',
    'transfer_labels',
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

GROUND = 0
# Label of a result face with no true surface within the distance gate.
OFF_SURFACE = -1

_CHUNK = 262_144
MAX_SPLIT_LEVELS = 6
MAX_PIECES = 8_000_000


@dataclass
class LabelTransfer:
    """True labels carried onto pieces of the faces of a result mesh.

    Faces longer than the sampling length are cut into pieces, so that one large triangle
    (a coarse ground patch, say) does not take a single label for all of its area.

    Attributes:
        face: Per piece, the index of the result face it belongs to.
        true_labels: Per piece, the label of the true surface nearest its centroid (rock id,
            0 for ground, -1 when none lies within the gate).
        distances: Per piece, distance from its centroid to the nearest true surface.
        areas: Per piece, its area (in the truth frame).

    """

    face: IntArray
    true_labels: IntArray
    distances: FloatArray
    areas: FloatArray


def _areas(tri: FloatArray) -> FloatArray:
    """Area of each of K triangles given as Kx3x3 corners."""
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    out: FloatArray = 0.5 * np.linalg.norm(cross, axis=1)
    return out


def split_faces(
    vertices: FloatArray, faces: IntArray, max_edge: float
) -> tuple[FloatArray, IntArray]:
    """Cut triangles at their edge midpoints, 1 into 4, until no edge is longer than ``max_edge``.

    Splitting stops after :data:`MAX_SPLIT_LEVELS` rounds or past :data:`MAX_PIECES` pieces, so a
    degenerate call cannot exhaust memory; the remaining long faces are then kept whole.

    Returns:
        Kx3x3 piece corners and, per piece, the index of the face it came from.

    """
    tri = vertices[faces]
    parent = np.arange(len(faces), dtype=np.int64)
    if max_edge <= 0:
        return tri, parent
    for _ in range(MAX_SPLIT_LEVELS):
        longest = np.linalg.norm(tri - np.roll(tri, -1, axis=1), axis=2).max(axis=1)
        big = longest > max_edge
        n_big = int(np.count_nonzero(big))
        if n_big == 0 or len(tri) + 3 * n_big > MAX_PIECES:
            break
        t = tri[big]
        # mid[:, k] is the midpoint of the edge from corner k to corner k + 1.
        mid = (t + np.roll(t, -1, axis=1)) / 2
        kids = np.stack(
            [
                np.stack([t[:, 0], mid[:, 0], mid[:, 2]], axis=1),
                np.stack([t[:, 1], mid[:, 1], mid[:, 0]], axis=1),
                np.stack([t[:, 2], mid[:, 2], mid[:, 1]], axis=1),
                mid,
            ]
        )
        tri = np.concatenate([tri[~big], kids.reshape(-1, 3, 3)])
        parent = np.concatenate([parent[~big], np.tile(parent[big], 4)])
    return tri, parent


def transfer_labels(
    vertices: FloatArray,
    faces: IntArray,
    scene: LabelledMesh,
    max_distance: float,
    max_edge: float | None = None,
) -> LabelTransfer:
    """Label the result surface (already in the truth frame) with the nearest true surface.

    Args:
        vertices: Result vertices in the truth frame.
        faces: Result faces.
        scene: The truth scene mesh.
        max_distance: Distance gate [m]; pieces whose centroid is further from every true surface
            get :data:`OFF_SURFACE`.
        max_edge: Faces with a longer edge are cut into pieces first (see :func:`split_faces`);
            None for ``max_distance``.

    """
    # Raycasting runs in float32: work relative to the scene's centre to keep millimetres in
    # frames whose origin is far away.
    origin = scene.vertices.mean(axis=0) if len(scene.vertices) else np.zeros(3)
    scene_vertices = (scene.vertices - origin).astype(np.float32)
    scene_faces = scene.faces.astype(np.uint32)
    raycaster = o3d.t.geometry.RaycastingScene()
    raycaster.add_triangles(
        o3d.core.Tensor.from_numpy(scene_vertices), o3d.core.Tensor.from_numpy(scene_faces)
    )
    pieces, parent = split_faces(vertices, faces, max_distance if max_edge is None else max_edge)
    centroids = pieces.mean(axis=1) - origin
    labels = np.empty(len(pieces), dtype=np.int64)
    distances = np.empty(len(pieces), dtype=np.float64)
    chunks = range(0, len(pieces), _CHUNK)
    for start in progress(chunks, desc='nearest true surface', total=len(chunks), unit='chunk'):
        query = centroids[start : start + _CHUNK]
        hit = raycaster.compute_closest_points(o3d.core.Tensor.from_numpy(query.astype(np.float32)))
        prim = hit['primitive_ids'].numpy().astype(np.int64)
        labels[start : start + len(query)] = scene.labels[prim]
        distances[start : start + len(query)] = np.linalg.norm(
            hit['points'].numpy().astype(np.float64) - query, axis=1
        )
    labels[distances > max_distance] = OFF_SURFACE
    return LabelTransfer(parent, labels, distances, _areas(pieces))


@dataclass(frozen=True)
class MatchOptions:
    """Thresholds of the rock matching.

    Attributes:
        min_iou: A result rock and a true rock match only when the intersection over union of
            their surfaces (on the result mesh) is at least this.
        visible_threshold: True rocks with a visible fraction below this are not counted as
            missed when undetected, and are left out of the "visible" precision and recall,
            with the result rocks about them (``RockMatching.on_hidden``).
        major_share: A merge is a result rock holding at least this share of the reconstructed
            surface of two or more true rocks; a split is a true rock on which two or more result
            rocks lie with at least this share of their own surface. A result rock with this
            share on one barely visible rock is about that rock.
        minor_share: ...provided each piece is at least this share of the other side (the
            result rock for a merge, the true rock for a split), so that slivers do not count.

    """

    min_iou: float = 0.5
    visible_threshold: float = 0.3
    major_share: float = 0.5
    minor_share: float = 0.1


@dataclass
class RockMatching:
    """Outcome of matching result rocks to true rocks.

    Attributes:
        result_ids: Result rock ids, the rows of ``overlap``.
        true_ids: True rock ids, the first columns of ``overlap``; then ground and off-surface.
        overlap: Area of each result rock on each true rock, on the ground and off any surface.
        result_area: Surface area of each result rock.
        true_area: Reconstructed surface area of each true rock (every result face labelled so).
        iou: Intersection over union of each result rock with each true rock.
        pairs: Matched (result id, true id, iou), one-to-one.
        merges: Result id to the true ids it merges.
        splits: True id to the result ids it is split into.
        false_reasons: Unmatched result id to what its surface mostly lies on
            (``"ground"``, ``"off-surface"``, ``"rock <id>"``, ``"no faces"``).

    """

    result_ids: list[int]
    true_ids: list[int]
    overlap: FloatArray
    result_area: FloatArray
    true_area: FloatArray
    iou: FloatArray
    pairs: list[tuple[int, int, float]]
    merges: dict[int, list[int]] = field(default_factory=dict)
    splits: dict[int, list[int]] = field(default_factory=dict)
    false_reasons: dict[int, str] = field(default_factory=dict)

    def on_hidden(self, hidden: set[int], share: float) -> list[int]:
        """Return the result rocks that are about barely visible true rocks, right or wrong.

        A result rock matched to one of ``hidden``, or unmatched with at least ``share`` of its
        surface on one of them (a piece of a rock the camera barely saw), is neither a hit nor
        a false rock for figures over the visible rocks: without the second half, finding a
        barely visible rock whole counted nothing while finding it in two pieces counted two
        false rocks.
        """
        cols = [j for j, t in enumerate(self.true_ids) if t in hidden]
        matched = {r: t for r, t, _ in self.pairs}
        out = []
        for i, rid in enumerate(self.result_ids):
            if rid in matched:
                about = matched[rid] in hidden
            else:
                on = self.overlap[i, cols].max() if cols else 0.0
                about = bool(self.result_area[i] > 0 and on >= share * self.result_area[i])
            if about:
                out.append(rid)
        return out

    def detection(
        self, counted: Collection[int], fines: Collection[int], share: float
    ) -> Detection:
        """Score the result against the true rocks ``counted``, the others being left aside.

        A true rock not in ``counted`` (barely visible, or under the smallest rock of interest)
        is neither missed nor, found, a hit; a result rock about one of them (see
        :meth:`on_hidden`) is not counted either way, but one that is about none of them and lies
        mostly (``share`` of its area) on several of ``fines`` is a false rock, and a cluster.
        """
        keep = set(counted)
        found = [(r, t) for r, t, _ in self.pairs if t in keep]
        aside = set(self.on_hidden(set(self.true_ids) - keep, share))
        fine = set(fines)
        small = [j for j, t in enumerate(self.true_ids) if t in fine]
        on_small = self.overlap[:, small].sum(axis=1)
        clusters = [
            rid
            for i, rid in enumerate(self.result_ids)
            if rid not in aside
            and self.result_area[i] > 0
            and on_small[i] >= share * self.result_area[i]
        ]
        return Detection(
            true_rocks=len(keep),
            result_rocks=len(self.result_ids) - len(aside),
            found=found,
            clusters=clusters,
        )


@dataclass(frozen=True)
class Detection:
    """Hits of a matching over the true rocks it counts.

    Attributes:
        true_rocks: True rocks counted.
        result_rocks: Result rocks counted (not about a true rock left aside).
        found: (result id, true id) of each counted true rock matched one to one.
        clusters: Result rocks lying mostly on several true rocks too small to count.

    """

    true_rocks: int
    result_rocks: int
    found: list[tuple[int, int]]
    clusters: list[int]

    @property
    def recall(self) -> float | None:
        """Counted true rocks found, over those counted (None without any)."""
        return len(self.found) / self.true_rocks if self.true_rocks else None

    @property
    def precision(self) -> float | None:
        """Counted true rocks found, over the result rocks counted (None without any)."""
        return len(self.found) / self.result_rocks if self.result_rocks else None


def _share(num: FloatArray, den: FloatArray) -> FloatArray:
    out: FloatArray = np.divide(num, den, out=np.zeros_like(num), where=den > 0)
    return out


def _index_of(values: IntArray, ids: list[int], missing: int) -> IntArray:
    """Position of each value in ``ids``, ``missing`` where it is not there."""
    uniq, inverse = np.unique(values, return_inverse=True)
    lookup = {v: i for i, v in enumerate(ids)}
    per_uniq = np.array([lookup.get(int(v), missing) for v in uniq], dtype=np.int64)
    out: IntArray = per_uniq[inverse.reshape(-1)]
    return out


def match_rocks(
    result_labels: npt.ArrayLike,
    transfer: LabelTransfer,
    result_ids: list[int],
    true_ids: list[int],
    options: MatchOptions,
) -> RockMatching:
    """Build the overlap matrix and assign result rocks to true rocks one to one.

    Args:
        result_labels: Per piece of ``transfer``, the result rock id of its face (0 or an id
            not in ``result_ids`` = unassigned).
        transfer: True labels of the pieces of the result surface.
        result_ids: Result rock ids (> 0).
        true_ids: True rock ids (> 0).
        options: Thresholds.

    """
    rlab = np.asarray(result_labels, dtype=np.int64)
    n_r, n_t = len(result_ids), len(true_ids)
    ground_col, off_col = n_t, n_t + 1
    rows = _index_of(rlab, result_ids, missing=n_r)
    tl = transfer.true_labels
    cols = _index_of(tl, true_ids, missing=ground_col)
    cols[tl == OFF_SURFACE] = off_col
    # One extra row collects unassigned result faces, which still count in the true rocks' areas.
    full = np.zeros((n_r + 1, n_t + 2))
    np.add.at(full, (rows, cols), transfer.areas)
    overlap = full[:n_r]
    result_area = overlap.sum(axis=1)
    true_area = full[:, :n_t].sum(axis=0)
    inter = overlap[:, :n_t]
    union = result_area[:, None] + true_area[None, :] - inter
    iou = _share(inter, union)

    pairs: list[tuple[int, int, float]] = []
    if n_r and n_t:
        score = np.where(iou >= options.min_iou, iou, 0.0)
        for i, j in zip(*linear_sum_assignment(score, maximize=True), strict=True):
            if score[i, j] > 0:
                pairs.append((result_ids[i], true_ids[j], float(iou[i, j])))

    of_true = _share(inter, np.broadcast_to(true_area, inter.shape))
    of_result = _share(inter, np.broadcast_to(result_area[:, None], inter.shape))
    merged = (of_true >= options.major_share) & (of_result >= options.minor_share)
    split = (of_result >= options.major_share) & (of_true >= options.minor_share)
    merges = {
        result_ids[i]: [true_ids[j] for j in np.flatnonzero(merged[i])]
        for i in range(n_r)
        if merged[i].sum() >= 2
    }
    splits = {
        true_ids[j]: [result_ids[i] for i in np.flatnonzero(split[:, j])]
        for j in range(n_t)
        if split[:, j].sum() >= 2
    }

    matched = {p[0] for p in pairs}
    names = [f'rock {t}' for t in true_ids] + ['ground', 'off-surface']
    false_reasons = {
        rid: names[int(np.argmax(overlap[i]))] if result_area[i] > 0 else 'no faces'
        for i, rid in enumerate(result_ids)
        if rid not in matched
    }
    return RockMatching(
        result_ids=list(result_ids),
        true_ids=list(true_ids),
        overlap=overlap,
        result_area=result_area,
        true_area=true_area,
        iou=iou,
        pairs=pairs,
        merges=merges,
        splits=splits,
        false_reasons=false_reasons,
    )
