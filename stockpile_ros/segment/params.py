"""The segmentation's parameters and the lengths they scale with.

The presets (``paper``, ``default``), every field's scale (median edge lengths of the mesh, or
multiples of the smallest rock of interest's b), and how that rock's b is found (the class being
checked, ``segment.min_rock_b`` or the mesh's resolution).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, replace
from typing import Annotated, Any, Literal

import numpy as np
import numpy.typing as npt

from ..ranges import Range
from .criterion import PAPER_THRESHOLD

__all__ = [
    'CLASS_MIN_SHARE',
    'EDGE_SAMPLES',
    'RESOLVABLE_EDGES',
    'RINGS_PER_EDGE',
    'SHARP_EDGES',
    'Mode',
    'RockScale',
    'SegmentParams',
    'asked_min_rock_b',
    'class_max_rock_b',
    'class_min_rock_b',
    'median_edge',
    'rock_scale',
]


F64 = npt.NDArray[np.float64]


Mode = Literal['paper', 'default']


#: Most faces whose edges give the median edge length (an even stride of the mesh's).
EDGE_SAMPLES = 65536


#: The least ``min_rock_edges`` can be set to: a rock under this many median edge lengths across
#: cannot be told from mesh noise even on a noise-free mesh.
RESOLVABLE_EDGES = 4.0

#: Median edge lengths across the smallest rock of interest from which the segmentation finds
#: rocks as it should: on bench/bench_yardstick.py's six 300-rock beds of angular rocks
#: (aggregate, cobble, riprap; seeds 1 and 2) recall was 0.81-0.89 at 20, 0.85-0.94 at 30 and
#: 0.93-0.96 at 40, precision 0.81-0.88, 0.89-0.94 and 0.93-0.95.
SHARP_EDGES = 40.0


#: Rings of faces a front crosses per median edge length of distance: across edge-neighbouring
#: triangles it advances about half an edge a ring (on a 300-rock bed, 90-97 % of the faces
#: within n/2 edge lengths of a region were reached after n rings, for n from 1 to 12).
RINGS_PER_EDGE = 2.0


#: When a class is checked, the smallest rock of interest is this share of the smallest size the
#: class names (the lower limit of its D15): the rocks under D15 carry 15 % of the mass and must
#: be counted for D15 to come out right.
CLASS_MIN_SHARE = 0.5


@dataclass(frozen=True)
class SegmentParams:
    """Every knob of the segmentation. Paper values in brackets; each length says its unit.

    Attributes:
        mode: Name of the preset these values came from. As a parameter: the preset that gives
            every other ``segment`` value not set explicitly.
        threshold: ``t`` of Eq. 2 [0.7; the authors' code used 0.81; 0.93 measured best here: on
            four reconstructed piles 0.90 merged touching rocks (recall 0.64 on one), 0.95 began
            to split single rocks].
        seed_order: ``"index"`` restarts at the lowest-numbered unvisited face [the paper names no
            order]; ``"convex"`` at the unvisited face whose outgoing edges score highest on average
            (the authors' code seeded among the most convex faces).
        normal_smoothing: Rounds of area-weighted averaging of each face normal with its neighbours'
            before the test [0].
        exclude_ground: Give faces on the ground plane label 0 and keep them out of the search [no;
            the authors removed the ground by hand].
        min_rock_b: Intermediate dimension b of the smallest rock of interest [m]; 0: half the
            smallest size of the class being checked (the lower limit of its D15) when a class is
            checked, else ``min_rock_edges`` median edge lengths. Never taken under
            ``min_rock_edges`` edge lengths.
        min_rock_edges: The smallest rock a mesh resolves: the smallest rock of interest when
            neither ``min_rock_b`` nor a class gives it, and its floor when one does [in median
            edge lengths; at least ``RESOLVABLE_EDGES`` (4)]. On reconstructed meshes the
            search's pieces of single rocks that no clean-up joins reach about this size
            (12-55 cm2, square roots of 9-19 edge lengths, on the demo pile): a class-derived
            ``min_rock_b`` of 12 edge lengths (class I on the demo pile, 3.8 mm edges) took the
            result from 14 to 18 rocks there even with every other floor; 20 kept 14. A point
            cloud sets it from its spacing (``cloud.min_rock_spacings``); another tool's mesh,
            when it is not set, has it lowered from here a factor sqrt 2 at a time while the
            sizes pile up against it (``stockpile_ros.segment.pipeline.settle_floor``).
        ground_tolerance_edges: Height above the ground (``z = 0``, or the open ground found, see
            ``max_rock_b``) under which a face is ground [in median edge lengths; 2 is the 1 cm
            fitted on reconstructed piles at the 4-5 mm median edge of a depth-9 Poisson mesh of
            a simulator scene (4.3 mm on the demo scene, 3.4-4.9 mm on bench/bench_scale.py's
            piles)].
        max_rock_b: Intermediate dimension b of the largest rock on the pile [m]; 0: the largest
            upper size limit of the class being checked when a class is checked, else unknown,
            and then the ground is the plane ``z = 0`` alone. Sets the open ground that follows
            the site (see ``ground_window_b``).
        ground_window_b: Width of the bare patch that open ground off the plane must hold, wider
            than any rock's plan (see :mod:`.ground`) [in units of ``max_rock_b``; 0: the plane
            alone]. On bench/bench_yardstick.py's riprap bed (0.3-1.5 m) over ground waving by
            half the largest b, at 20 edges across the smallest b: 1.0 and 1.25 found 96 % of
            the bare ground, calling 0.06 % and 0.05 % of the rock faces ground; 2.3 found none
            (no bare patch of that bed holds a square that wide); at 12 edges 1.0-2.3 found 97 %,
            4 none.
        ground_min_nz: Smallest normal z component of a ground face (0: any face that does not
            face down; the skirt Poisson puts round the foot of a rock slopes).
        min_region_share: Regions of less area than this share of the plan area of the smallest
            rock of interest (a disc of diameter ``min_rock_b``) are fragments; 0 keeps every
            region [in units of ``pi / 4 min_rock_b^2``] [0; the authors' code dropped regions
            under 1 % of all faces, a rule that caps a pile at about 100 rocks]. 1: a rock of
            interest shows at least its plan area unless it is mostly hidden. On reconstructed
            piles the pieces of single rocks that survive the convex join are up to about that
            size: with 0.25 the demo pile gave 24 rocks for 14 (12 false, every one on a true
            rock, 13-170 cm2) and one of 12 rocks gave 30; 0.5 gave 15 and 17, 1.0 14 and 14
            (2 and 3 false), 1.5 and 2 the same. On bench/bench_scale.py's coarse pile (150 rocks
            of 11-22 edge lengths across) discs of 10 to 20 edge lengths across lost no rock
            (1.0 of the default 20 edges: recall/precision 0.986/0.989 on coarse, 0.990/0.992 on
            many, as with 0.25), discs of 28 and 30 lost 32 and 45.
        merge_fragments: Merge fragments into the neighbouring region they share the most edges
            with; when off, or when a fragment has no neighbour, it gets label 0 [off].
        neck_radii: After the fragment merge, each region is eroded by this many valley radii
            from its outline (its borders with other regions, valley and ground faces and the
            mesh's edge; counted in rings of faces, ``RINGS_PER_EDGE`` a median edge), and where
            what is left falls into two or more parts of at least a fragment's area each (see
            ``min_region_share``), the region is split into them at the necks between them (see
            ``split_at_necks``) [in valley radii; 0: no split] [off]. The search runs from one
            rock into the next through a gap in the valley band between them, a pass narrower
            than the band is wide; a rock with a waist that narrow between two parts that large
            is rare, and two parts of one rock split here can meet again at the convex join. On
            bench/bench_yardstick.py's 300-rock beds (seeds 1 and 2, 20 and 30 edges across the
            smallest b) 1 radius raised recall and precision on all twelve rows, recall by
            0.008-0.075 (aggregate, seed 1, 20 edges: 0.783/0.810 -> 0.858/0.844); 0.75 radii
            measured within 0.02 of it and 1.25 lower (mean recall over the six rows at 20
            edges 0.847, 0.844, 0.831). Parts of half a fragment found more on the beds (cobble,
            seed 2, 20 edges: 0.861/0.849 against 0.825/0.837) but cut single rocks of the
            reconstructed piles where their surface dips (one of 14 rocks into four): a
            fragment left those piles as they were but one, where a merge of two rocks was split
            and a single rock was (recall 0.93 -> 1.0, precision 0.87 -> 0.82).
        fragment_min_border: Least share of a fragment's outline (its edges to every other face,
            valley and ground faces included) that it must share with a region to be merged into
            it; a fragment that touches its best neighbour along less gets label 0 rather than
            make a wrong rock of two [a share of the fragment's own outline; 0: any border]
            [off]. Two fragments join whatever their border. On bench/bench_yardstick.py's
            300-rock beds at 20 edges across the smallest b, 0 -> 0.1 took recall/precision from
            0.783/0.839 to 0.808/0.882 (aggregate), 0.842/0.856 to 0.858/0.880 (cobble) and
            0.891/0.883 to 0.899/0.892 (riprap), regions holding two true rocks from 21, 25 and 15
            to 15, 11 and 6: most small rocks merged into a neighbour had reached it along 1-5
            edges, under 0.07 of their outline. On aggregate 0.08-0.2 gave the same recall; on
            the demo's reconstruction the pieces of single rocks share 0.09 of their outline and
            more, 0.08-0.12 left its 14 rocks as they were (0.929/0.929) and 0.2 lost one.
        drop_facing_down: Give label 0 to a region that borders no other region (only ground)
            and whose area-weighted mean normal points down [off]: the cameras look down on a
            pile, so a rock standing alone on the ground shows its top; a lone region facing down
            is an underside or overhang cut off from its rock by a gap in the mesh. On two
            reconstructed piles such regions (2047 faces, median normal z -0.19, on a 12-rock
            pile; 1224 faces, -0.29, on an 11-rock one) were reported as false rocks. Regions
            facing down that border others are left alone: on bench/bench_scale.py's many pile,
            merging those into a neighbour too gave 123 segments for 150 rocks (precision 0.81).
        hull_split: Before the convex join, split each region at its faces deeper under its own
            convex hull than the join's ``border_depth`` of the square root of a fragment's area
            (see ``min_region_share``; never under ``depth_min_edges``), where the rest falls into
            two or more parts of at least a fragment's area each (see ``split_under_hulls``) [off].
            One convex rock lies on its hull; two touching rocks that the search ran across (their
            crease too wide and shallow for the valley test at its radius) have the crease under
            theirs. At that depth the join keeps a part of that area apart, so the two steps agree.
            Valley faces neither shape the hull nor hold a part together: handed back, they are the
            flanks of a crevice and of the rock beyond it, not evidence of a rock (with them, a
            neighbour's flank became a part and cut large partly buried riprap; with only the far
            ones left out, one of the five reconstructed piles lost a rock to a cut). On
            bench/bench_yardstick.py's 300-rock beds (seeds 1 and 2, 20 and 30 edges across the
            smallest b, twelve rows) the mean recall rose from 0.872 to 0.883 and the mean precision
            from 0.873 to 0.877 (riprap, seed 1, 20 edges: 0.857/0.836 -> 0.882/0.854; cobble, seed
            2, 30 edges: 0.876/0.876 -> 0.905/0.886; lower on one row, riprap seed 2 at 20 edges,
            0.800/0.812 -> 0.800/0.800); the five reconstructed piles and bench/bench_scale.py's six
            segment as before. A region the depth cuts into parts all smaller than a fragment
            is several small rocks taken for one and is left out: where the smallest rock of
            interest lies above a bed's smallest rocks (``bench_yardstick.py --floor 1.5`` and
            ``2``, seeds 1 and 2, 20 and 30 edges, 24 rows) precision rose on every row
            (0.455-0.902 -> 0.577-0.949, mean +0.10) and recall moved on three by one rock (two
            down, one up); the clusters of fines reported fell from 228 to 121. On the twelve
            rows without fines precision rose by up to 0.018 and one rock was lost (riprap seed
            2, 20 edges, recall 0.808 -> 0.800); on the five reconstructed piles mean precision
            rose from 0.839 to 0.895 (seeds 21, 22 and 24 one false rock fewer, seed 23 three),
            recall as before. Leaving such a region out only where its largest part held under
            half of it caught two thirds as many (clusters 160) and lost no rock.
        merge_convex: After the fragment merge, join neighbouring regions whose union is convex
            across their shared border (see ``merge_convex_borders``) [off]: on a
            reconstructed mesh, noise stops the search inside single rocks.
        convex_fragments: The fragments the fragment merge leaves out (see
            ``fragment_min_border``) take part in the convex join, each a region of its own, and
            are left out after it unless joined to a region [off]. The search cuts pieces off
            large rocks along noise, and those touching the rock along under a tenth of their
            outline were lost from it: on bench/bench_yardstick.py's riprap bed (seed 1, 40 edges
            across the smallest b) the matched rocks' masses summed to 0.90 of those measured on
            the true labels, the largest rocks short of a tenth of their seen surface, and the D50
            came out 7.6 % low. Joined where convex, they come back; a small rock wedged between
            larger ones is not convex with them and stays out. Over the twelve rows of seeds 1
            and 2 at 20 and 30 edges recall rose on 7 and fell on none (mean 0.883 -> 0.889),
            precision rose on 8 and fell on one (aggregate, seed 1, 20 edges, 0.869 -> 0.862;
            mean 0.877 -> 0.885); at 40 edges riprap seed 1 went from 0.941/0.896 to 0.958/0.927
            (D50 -7.6 -> -3.5 %), aggregate seed 2 from 0.917/0.891 to 0.947/0.926, riprap seed
            2's D50 from -7.6 to +0.2 %. The five reconstructed piles: one false rock fewer on one
            (seed 21); bench/bench_cloud.py's survey and bench/bench_segment.py's pile as before.
        border_depth: Largest median depth of the shared border under the convex hull of the
            union (along the border's outward normal), for a join [in units of the square root
            of the smaller region's area]. On four reconstructed piles 0.12 joined every split
            rock and no touching rocks; 0.16 began to join touching rocks, 0.05 left splits. On
            bench/bench_yardstick.py's 300-rock beds at 20 edges across the smallest b, 13 of
            the 15 joins 0.12 made on cobble were of touching rocks; 0.08 took recall/precision
            from 0.76/0.69 to 0.80/0.71 (cobble) and 0.83/0.76 to 0.84/0.76 (riprap), aggregate
            unchanged, and still joined both split rocks of the demo pile (14 rocks as before).
        border_min_edges: Borders shorter than this many face edges are never joined (a corner
            contact says little about the surface between the regions).
        depth_min_edges: Least depth the convex join and the hull split take as a crease: a
            depth under a hull is never compared with less than this [in median edge lengths:
            a Poisson surface resolves nothing finer than its cell, about an edge, and a border
            shallower than that lies in its noise]. It binds only where a fragment's join depth
            (``border_depth`` of a fragment's root area, 0.071 ``min_rock_b``) is under it: a
            smallest rock under 14 edge lengths, as a cloud's 10 resolutions give (see
            ``cloud.min_rock_spacings``); the photo route's floor of 20 leaves it idle. On a 1.2
            M-point survey at 2.8 mm of 220 rocks of 10-35 cm (bench/bench_cloud.py --spacing
            0.0025, meshed at its spacing before ``cloud.noise_sigmas``; smallest rock 9 edge
            lengths) 0 reported 794 rocks for 203 found, 528 of the
            others pieces of found rocks whose borders lay a median 0.93 edge lengths deep (0.087
            of their root area); 1 reported 593 (1.5: 429, but 1.5 binds at 20 edges too); at
            7.5 mm (smallest rock 10 edge lengths) 215 for 198 found became 214.
        valley_depth_ratio: Faces whose vertices lie deeper than this under their smoothed
            surroundings are valley faces, kept out of the search and handed back to the regions
            they border afterwards; 0 disables [in units of the valley radius, a crease angle:
            0.067 is the 0.5 mm at 7.5 mm measured on reconstructed piles] [0]. On seven
            reconstructed piles (79 matched rocks) 0.5 mm took recall from 0.86 to 0.90, the
            median b error from 7.0 % to 5.4 % and the mean D50 error from 9.8 % to 4.3 %; 0.3 mm
            and 0.7 mm did worse on b or D50.
        valley_radius_b: Scale of the smoothed surroundings: the standard deviation of the
            smoothing kernel [in units of ``min_rock_b``; on reconstructed piles (depth-9 meshes,
            4-5 mm edges) 7.5 mm, about 1.5 edge lengths, measured as well as 5 and 10 mm: 0.075
            keeps it there when ``min_rock_b`` comes from the mesh]. A crease is only seen at a
            scale wider than the rounding Poisson gave it, and the crevices between larger rocks
            are wider. Never under ``valley_min_edges`` edge lengths.
        valley_min_edges: Floor of the valley radius [in median edge lengths]. On flat ground of
            three reconstructed piles (3.8, 2.0, 2.35 mm edges) the depth under the smoothed
            surface grows with the radius up to about 3 edge lengths (the noise of the dense
            points is correlated over a few cells) and then levels off near 0.15 edge lengths,
            while the valley depth threshold keeps growing with the radius: 11-17 % of the flat
            faces read as valley at 1 edge length, 9-15 % at 1.5, 4-6 % at 3, 2-5 % at 4, where
            the threshold clears the 95th percentile of the flat ground's depth. On the 12-rock
            pile of 2.0 mm edges, 1.5 edge lengths (those of a 20-edge rock of interest) left 3
            false rocks, 2.5 to 4 left 1; on the demo pile, 3 joined two touching rocks (D50
            +8 %), 2.5 and 4 did not, and 4 found one rock more (recall 0.93 against 0.86). The
            7.5 mm of the absolute rule were 2 and 3.7 edge lengths on those two piles.
        valley_reach: Valley faces farther than this from every region of the search are left
            out of every rock (label 0) after the clean-ups, which see them handed back [in valley
            radii, counted in rings of faces round each region, ``RINGS_PER_EDGE`` a median edge;
            0: every valley face is handed back]. Between touching rocks a valley is about a
            radius wide either side of its middle; what lies farther is mostly the exposed part
            of rocks the search found no region on (partly buried ones in the gaps), and handed
            back it went to whichever region reached it first: on bench/bench_yardstick.py's
            300-rock beds at 20 edges across the smallest b, one cobble region took parts of 12
            rocks, and 1 radius took recall/precision from 0.68/0.59 to 0.76/0.69 (cobble),
            0.71/0.66 to 0.78/0.78 (aggregate) and 0.80/0.71 to 0.83/0.76 (riprap), the found
            rocks' median mass over the true from 1.32 to 1.27 (cobble) and 1.61 to 1.41
            (riprap); 0.5 radii measured within 0.02 of it. Within the reach the fronts only go
            down into a valley (each face they take at least as deep as the one they come from):
            a rock's flank runs down to the valley's floor, and what rises beyond it is the top of
            a rock sunk between others (on the cobble bed 61 % of the valley faces lie on rocks
            under 30 % visible, 57 % of those rocks' surface is valley). On the harder yardstick
            (0.6 cells of noise, estimated normals; seeds 1 and 2, 20 and 30 edges, 12 rows) this
            raised recall or precision on 7 rows by up to 0.04 (cobble, seed 1, 20 edges:
            0.817/0.838 -> 0.858/0.880) and lowered neither on any; on the five reconstructed
            piles detections stayed as they were but for one false rock fewer on seed 24.
        far_valley_pieces: The valley faces beyond ``valley_reach`` are cut by the search (Eq.
            2 among themselves) into pieces that take part in the convex join as the fragments
            left out do (``convex_fragments``), and are left out unless joined to a region; off,
            they are handed back whole to the regions they border for the clean-ups and left out
            of every rock at the end [off]. Handed back, they bring the exposed tops of the sunk
            rocks round a partly buried rock into the hulls of its pieces, which are then not
            convex together: on bench/bench_yardstick.py's aggregate bed (seed 2, 40 edges
            across the smallest b) the rocks 30-50 % visible kept 0.49-0.81 of their seen surface
            in one region and the D50 came out 13 % low; as pieces, up to 0.86, and -0.2 %
            (recall/precision 0.947/0.926 -> 0.947/0.947). Off by default because it trades
            split rocks for joined ones: over the eighteen rows of seeds 1 and 2 at 20, 30 and
            40 edges the mean recall went 0.907 -> 0.904, precision 0.902 -> 0.908, the mean
            D50 error -3.7 -> -1.9 % (mean |D50 error| 4.2 -> 3.5 %), but regions of two rocks
            180 -> 207 and rocks in pieces 90 -> 76 (without the far faces the join judges two
            touching rocks on the short stretch where they meet directly), and riprap seed 1 at
            40 edges D50 -3.5 -> -7.6 %; on the five reconstructed piles precision 0.851 ->
            0.878, recall 0.929 -> 0.917 (seed 21: two rocks joined); bench/bench_scale.py's six
            piles and bench/bench_cloud.py's survey as they were; 1.1-1.2 times the time on
            bench/bench_segment.py's 1.08 M-face pile.
        split_depth_ratio: Faces deeper than this under their surroundings at the scale
            ``split_radius_b`` cut a region; where they cut it into two or more parts of at
            least ``split_min_share`` of its area each, the parts become regions of their own (see
            ``split_at_valleys``); 0 disables [in units of the split radius] [0; off by default].
            On twelve reconstructed piles 1 mm at 15 mm (0.067) split one region, two touching
            rocks joined through a gap in the narrower valley (recall 0.905 -> 0.912, median b
            error 5.1 % -> 4.8 %, worst D50 error 16.4 % -> 6.9 %). The neck split
            (``neck_radii``) now parts such rocks earlier, and 0.067 after it only cut rocks: on
            bench/bench_yardstick.py's twelve rows (seeds 1 and 2, 20 and 30 edges) 0 took
            precision up on eight (by 0.006-0.031) and down on one (by 0.001), recall up on five
            and down on one (cobble, seed 1, 20 edges: 0.883 -> 0.875), the D50 error of seed
            2's aggregate bed from -10.4 to -6.3 % and -8.4 to -2.7 % at 20 and 30 edges; the
            five reconstructed piles of the README and bench/bench_scale.py's six came out the
            same, and the default mode runs without the split radius's smoothing.
        split_radius_b: Scale of the surroundings for ``split_depth_ratio`` [in units of
            ``min_rock_b``; 0.15 is the 15 mm (3 edge lengths) measured on reconstructed piles
            when ``min_rock_b`` comes from the mesh]. Never under ``split_min_edges`` edge lengths.
        split_min_edges: Floor of the split radius [in median edge lengths; twice
            ``valley_min_edges``, as ``split_radius_b`` is twice ``valley_radius_b``].
        split_min_share: Smallest share of a region's area that a part needs to be split off
            (0.2 measured the same as 0.1).

    """

    mode: Mode = 'default'
    threshold: Annotated[float, Range(-1.0, 2.0)] = 0.93
    seed_order: Literal['index', 'convex'] = 'convex'
    normal_smoothing: Annotated[int, Range(0, 100)] = 0
    exclude_ground: bool = True
    min_rock_b: Annotated[float, Range(0.0, 100.0)] = 0.0
    min_rock_edges: Annotated[float, Range(RESOLVABLE_EDGES, 10_000.0)] = 20.0
    ground_tolerance_edges: Annotated[float, Range(0.0, 1000.0)] = 2.0
    max_rock_b: Annotated[float, Range(0.0, 100.0)] = 0.0
    ground_window_b: Annotated[float, Range(0.0, 100.0)] = 1.25
    ground_min_nz: Annotated[float, Range(0.0, 1.0)] = 0.0
    min_region_share: Annotated[float, Range(0.0, 100.0)] = 1.0
    merge_fragments: bool = True
    neck_radii: Annotated[float, Range(0.0, 100.0)] = 1.0
    fragment_min_border: Annotated[float, Range(0.0, 1.0)] = 0.1
    drop_facing_down: bool = True
    hull_split: bool = True
    merge_convex: bool = True
    convex_fragments: bool = True
    border_depth: Annotated[float, Range(0.0, 10.0)] = 0.08
    border_min_edges: Annotated[int, Range(0, 100_000_000)] = 5
    depth_min_edges: Annotated[float, Range(0.0, 100.0)] = 1.0
    valley_depth_ratio: Annotated[float, Range(0.0, 10.0)] = 0.067
    valley_radius_b: Annotated[float, Range(0.001, 1.0)] = 0.075
    valley_min_edges: Annotated[float, Range(0.0, 100.0)] = 4.0
    valley_reach: Annotated[float, Range(0.0, 100.0)] = 1.0
    far_valley_pieces: bool = False
    split_depth_ratio: Annotated[float, Range(0.0, 10.0)] = 0.0
    split_radius_b: Annotated[float, Range(0.001, 1.0)] = 0.15
    split_min_edges: Annotated[float, Range(0.0, 100.0)] = 8.0
    split_min_share: Annotated[float, Range(0.0, 0.5)] = 0.1

    @classmethod
    def paper(cls) -> SegmentParams:
        """Return the published rule: ``t = 0.7``, face normals, index-order seeds, no clean-up."""
        return cls(
            mode='paper',
            threshold=PAPER_THRESHOLD,
            seed_order='index',
            normal_smoothing=0,
            exclude_ground=False,
            min_region_share=0.0,
            merge_fragments=False,
            neck_radii=0.0,
            fragment_min_border=0.0,
            drop_facing_down=False,
            hull_split=False,
            merge_convex=False,
            convex_fragments=False,
            valley_depth_ratio=0.0,
            split_depth_ratio=0.0,
        )

    @classmethod
    def preset(cls, mode: Mode, **overrides: Any) -> SegmentParams:
        """Return the ``mode`` preset with some fields replaced (``None`` values are ignored)."""
        base = cls.paper() if mode == 'paper' else cls()
        return replace(base, **{k: v for k, v in overrides.items() if v is not None})

    def as_dict(self) -> dict[str, Any]:
        """Plain dict for report.json."""
        return asdict(self)


@dataclass(frozen=True)
class RockScale:
    """The lengths a segmentation was measured against.

    Attributes:
        edge: Median edge length of the mesh [m] (0 when every edge is degenerate).
        min_rock_b: Intermediate dimension b of the smallest rock of interest [m].
        source: Where ``min_rock_b`` came from: ``"parameter"``, ``"class"`` or ``"mesh"``.
        requested: The smallest rock of interest asked for [m]; ``min_rock_b`` is larger when
            the mesh does not resolve it (see ``SegmentParams.min_rock_edges``).
        valley_radius: Scale of the valley faces (``SegmentParams.valley_radius_b``) [m].
        split_radius: Scale of the valleys that split a region (``split_radius_b``) [m].
        max_rock_b: Intermediate dimension b of the largest rock on the pile [m]; 0: unknown.

    """

    edge: float
    min_rock_b: float
    source: Literal['parameter', 'class', 'mesh']
    requested: float
    valley_radius: float
    split_radius: float
    max_rock_b: float = 0.0

    def as_dict(self) -> dict[str, Any]:
        """Plain dict for report.json."""
        return asdict(self)


def median_edge(vertices: F64, faces: npt.NDArray[np.int64]) -> float:
    """Median length of the mesh's face edges, degenerate (zero-length) edges left out [m].

    Returns:
        The median, 0 when the mesh has no edge of non-zero length.

    """
    # An even stride of faces gives the median of a million-face mesh to a fraction of a percent
    # at a small share of the cost; the same faces are picked whatever the mesh's size in metres.
    sample = faces[:: max(1, -(-len(faces) // EDGE_SAMPLES))]
    a, b = sample.ravel(), sample[:, [1, 2, 0]].ravel()
    # Summed a coordinate at a time, x then y then z as a norm sums them: half the cost of
    # gathering whole rows, and the same lengths.
    square = np.zeros(len(a))
    for column in np.ascontiguousarray(vertices.T):
        side = column[a] - column[b]
        square += side * side
    length = np.sqrt(square)
    length = length[length > 0]
    return float(np.median(length)) if len(length) else 0.0


def class_min_rock_b(spec: Mapping[str, Any]) -> float | None:
    """Smallest rock of interest for checking a class: half its smallest lower size limit.

    Args:
        spec: A class entry of the class table (``limits`` in metres, see ``load_class_table``).

    Returns:
        ``CLASS_MIN_SHARE`` times the smallest lower limit [m], None when the class has none.

    """
    lows = [float(lo) for lo, _ in spec.get('limits', {}).values() if lo is not None]
    return CLASS_MIN_SHARE * min(lows) if lows else None


def class_max_rock_b(spec: Mapping[str, Any]) -> float | None:
    """Largest rock a class allows: its largest upper size limit.

    Args:
        spec: A class entry of the class table (``limits`` in metres, see ``load_class_table``).

    Returns:
        The largest upper limit [m], None when the class has none.

    """
    highs = [float(hi) for _, hi in spec.get('limits', {}).values() if hi is not None]
    return max(highs) if highs else None


def asked_min_rock_b(
    params: SegmentParams, spec: Mapping[str, Any] | None = None
) -> tuple[Literal['parameter', 'class'], float] | None:
    """Return the smallest rock of interest asked for, and where from; None when none was.

    ``min_rock_b`` when given, else the class's (:func:`class_min_rock_b`) when one is checked.
    """
    if params.min_rock_b > 0:
        return 'parameter', params.min_rock_b
    from_class = class_min_rock_b(spec) if spec is not None else None
    return None if from_class is None else ('class', from_class)


def rock_scale(
    params: SegmentParams, edge: float, spec: Mapping[str, Any] | None = None
) -> RockScale:
    """Return the smallest rock of interest: ``min_rock_b``, else the class's, else the mesh's.

    The largest rock is ``max_rock_b``, else the class's largest upper limit, else unknown (0).

    Args:
        params: ``min_rock_b``, ``max_rock_b`` (0: not given) and ``min_rock_edges``.
        edge: The mesh's median edge length [m].
        spec: The class being checked, or None.

    Returns:
        The scale; ``min_rock_b`` is never under ``min_rock_edges`` edge lengths, the valley and
        split radii never under ``valley_min_edges`` and ``split_min_edges``.

    """
    floor = params.min_rock_edges * edge
    asked = asked_min_rock_b(params, spec)
    source: Literal['parameter', 'class', 'mesh'] = 'mesh'
    requested = floor
    if asked is not None:
        source, requested = asked
    b = max(requested, floor)
    largest = params.max_rock_b or (class_max_rock_b(spec) if spec is not None else None) or 0.0
    return RockScale(
        edge,
        b,
        source,
        requested,
        max(params.valley_radius_b * b, params.valley_min_edges * edge),
        max(params.split_radius_b * b, params.split_min_edges * edge),
        largest,
    )
