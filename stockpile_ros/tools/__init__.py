"""Tools around the measuring path, never on it: the simulator, the evaluation, test yardsticks.

- :mod:`.sim`: rendered cart recordings of synthetic rock piles, with exact truth
  (``stockpile simulate``);
- :mod:`.evaluation`: a result scored against simulator truth (``stockpile evaluate``);
- :mod:`.synthetic`: small piles of ellipsoids meshed without photogrammetry, with the true label
  of every face, and :mod:`.scoring`: a segmentation against those labels (tests, benches);
- :mod:`.reference_bfs`: the paper's search as written, the reference the vectorised search is
  tested against.

Nothing under ``stockpile_ros`` outside this package and the two commands imports it.
"""
