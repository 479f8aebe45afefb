"""Metric scale from one printed marker: a photo set and a video of the same walk round a pile.

Walk ``test`` is tests/test_photos.py's scene and walk (16 photos with a phone-like EXIF, names
shuffled; the same walk filmed as 40 MJPG frames, self-calibrated, keyframes as the test picks
them); ``wide`` and ``low`` are other scenes, walks and marker places, held out from the
test's. Per walk and capture: keyframes, registered,
the focal length's error, the scale error against the true camera centres, the stated
uncertainty (one standard deviation), the error in stated uncertainties (z), the scale error
against the pile's own sparse points (see :func:`pile_scale`) and its z, and the parts.
Then, with the true poses and camera (so only the corners are judged),
the marker scale from cv2.aruco's cornerSubPix corners (the baseline, measured in this run) and
from the edge-fitted corners :func:`~stockpile_ros.recon.scale.detect_markers` gives.

Usage:
    .venv/bin/python bench/bench_marker_scale.py [--walks test wide low] [--work DIR]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np
import pycolmap

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / 'tests'))

from recon_synth import look_at, scene_mesh
from test_photos import CAM, LOOK_AT, MARKER, WALKS, H, W, Walk, write_photos

from stockpile_ros.artefacts import WorkFolder
from stockpile_ros.geometry import umeyama
from stockpile_ros.recon.keyframes import KeyframeStore
from stockpile_ros.recon.scale import (
    MarkerDetections,
    MarkerSpec,
    detect_markers,
    parse_targets,
    scale_from_markers,
    triangulate,
)
from stockpile_ros.recon.scaling import estimate_scale
from stockpile_ros.recon.sfm import load_sparse
from stockpile_ros.recon.stages import photo_names, run_keyframes, run_sfm_stage
from stockpile_ros.settings import build_settings

FRAMES = 40


def photos(walk: Walk, mesh: object, folder: Path) -> dict[str, float]:
    """16 EXIF JPEGs along the walk; the walk parameter t of each file."""
    folder.mkdir(parents=True)
    return write_photos(folder, lambda t: walk.view(mesh, t))


def video(walk: Walk, mesh: object, path: Path) -> None:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*'MJPG'), 10.0, (W, H))
    for i in range(FRAMES):
        writer.write(cv2.cvtColor(walk.view(mesh, i / (FRAMES - 1)), cv2.COLOR_RGB2BGR))
    writer.release()


def subpix_markers(image: np.ndarray) -> MarkerDetections:
    """The baseline: cv2.aruco's own corners refined by cornerSubPix."""
    grey = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    code = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    corners, ids, _ = cv2.aruco.ArucoDetector(code, params).detectMarkers(grey)
    if ids is None:
        return {}
    return {('DICT_4X4_50', int(i)): np.asarray(c, np.float64).reshape(4, 2)
            for i, c in zip(np.ravel(ids), corners, strict=True)}  # fmt: skip


def capture(
    label: str,
    walk: Walk,
    source: Path,
    work: WorkFolder,
    values: dict[str, object],
    where: dict[str, float],
) -> list[str]:
    """Print the capture's line; return its corner lines."""
    options = build_settings(values).recon
    counts = run_keyframes(source, work, options)
    report = run_sfm_stage(work, options)
    store = KeyframeStore(work.keyframes)
    if where:
        t = {k: where[v] for k, v in photo_names(work).items()}
    else:
        t = {r.file: r.index / (FRAMES - 1) for r in store.records}
    model = load_sparse(work.sparse)
    scale, _ = estimate_scale(work, model, options)
    names = [k for k in t if k in model.views]
    true = umeyama(np.array([model.views[k].center for k in names]),
                   np.array([walk.centre(t[k]) for k in names])).scale  # fmt: skip
    focal = next(iter(model.views.values())).camera.fx / CAM.fx - 1
    parts = ', '.join(f'{k} {100 * v:.2f}' for k, v in scale.parts.items() if v is not None)
    rel = scale.rel_uncertainty or float('nan')
    error = scale.metres_per_unit / true - 1
    pile = scale.metres_per_unit / pile_scale(work, walk, t) - 1
    print(f'{label:13s} {counts.frames:6d} {counts.keyframes:9d} '
          f'{report.registered:10d} {100 * focal:+7.2f} '
          f'{100 * error:+8.3f} {100 * rel:7.3f} {error / rel:+5.2f} {100 * pile:+7.3f} '
          f'{pile / rel:+5.2f}   {parts}',
          flush=True)  # fmt: skip
    return corners(label, walk, store, t)


def pile_scale(work: WorkFolder, walk: Walk, t: dict[str, float]) -> float:
    """Metres per model unit of the sparse points on and round the pile (within 1 m of its centre).

    Their true places are triangulated from the same image points with the true cameras. With
    a focal length off the truth the model is no similarity of the world: the scene shrinks or
    grows against the camera path, and the pile (the rocks measured) is scaled by what lies near
    it, the marker, more nearly than the camera centres say.
    """
    rec = pycolmap.Reconstruction(str(work.sparse))
    true = {i: look_at(walk.centre(t[rec.image(i).name]), LOOK_AT) for i in rec.reg_image_ids()
            if rec.image(i).name in t}  # fmt: skip
    model, world = [], []
    for point in rec.points3D.values():
        rays = [(CAM, *true[e.image_id],
                 np.asarray(rec.image(e.image_id).points2D[e.point2D_idx].xy) - 0.5)
                for e in point.track.elements if e.image_id in true]  # fmt: skip
        place = triangulate(rays, 1.0) if len(rays) >= 3 else None
        if place is not None and np.linalg.norm(place[:2]) < 1.0:
            model.append(np.asarray(point.xyz))
            world.append(place)
    return umeyama(np.array(model), np.array(world)).scale


def corners(label: str, walk: Walk, store: KeyframeStore, t: dict[str, float]) -> list[str]:
    """Marker scale with the true poses and camera: the corners alone, baseline and edges."""
    specs = [s for s in parse_targets(MARKER) if isinstance(s, MarkerSpec)]
    poses = {}
    found: dict[str, dict[str, MarkerDetections]] = {'subpix': {}, 'edges': {}}
    for record in store.records:
        if record.file not in t:
            continue
        image = store.image(record)
        poses[record.file] = (CAM, *look_at(walk.centre(t[record.file]), LOOK_AT))
        found['subpix'][record.file] = subpix_markers(image)
        found['edges'][record.file] = detect_markers(image, ['DICT_4X4_50'])
    lines = []
    for method, detections in found.items():
        estimate = scale_from_markers(detections, poses, specs)
        error = float('nan') if estimate is None else 100 * (estimate.metres_per_unit - 1)
        lines.append(f'{label:13s} {method:7s} {error:+8.3f}')
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--walks', nargs='+', choices=list(WALKS), default=list(WALKS))
    parser.add_argument('--work', type=Path, help='folder for the captures (default: a new one)')
    args = parser.parse_args()
    root = args.work or Path(tempfile.mkdtemp(prefix='bench_marker_scale_'))
    print(f'work: {root}')
    print('walk, source  frames keyframes registered focal %  scale %  stated %     z'
          '  pile %     z   parts %')  # fmt: skip
    lines = []
    for name in args.walks:
        walk, folder = WALKS[name], root / name
        mesh = scene_mesh(walk.seed)
        where = photos(walk, mesh, folder / 'photos')
        lines += capture(f'{name} photos', walk, folder / 'photos', WorkFolder(folder / 'pw'),
                         {'recon.target': MARKER}, where)  # fmt: skip
        video(walk, mesh, folder / 'walk.avi')
        values = {'recon.target': MARKER, 'selector.min_parallax': 0.03, 'selector.min_spacing': 1}
        lines += capture(f'{name} video', walk, folder / 'walk.avi', WorkFolder(folder / 'vw'),
                         values, {})  # fmt: skip
    print('\nwith the true poses and camera (scale error %, the corners alone):')
    print('\n'.join(lines))


if __name__ == '__main__':
    main()
