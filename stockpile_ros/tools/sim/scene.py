"""A complete simulated scene: the pile, its textures, the ground and the calibration board."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .pile import PileConfig, PlacedRock, build_pile
from .texture import BoardTexture, GroundTexture, RockTextures

__all__ = ['Scene', 'SceneConfig', 'build_scene', 'place_board']


@dataclass(frozen=True)
class SceneConfig:
    """Parameters of a scene.

    Attributes:
        pile: The pile.
        target: Lay a ChArUco board on the ground beside the pile.
        board: Board layout (its placement is computed).
        board_bearing: World direction (yaw, rad) from the pile centre towards the board.
        board_gap: Clear ground between the outermost rock and the board [m].
        ground_px: Side of the tiled ground texture [px] (2 mm per texel).

    """

    pile: PileConfig = field(default_factory=PileConfig)
    target: bool = True
    board: BoardTexture = field(default_factory=BoardTexture)
    board_bearing: float = -np.pi / 2 + 0.5
    board_gap: float = 0.12
    ground_px: int = 2048


@dataclass
class Scene:
    """Everything a renderer and the truth need.

    Attributes:
        rocks: Rocks at rest.
        rock_textures: Their solid textures.
        ground: Ground texture.
        board: The board as placed, or None.

    """

    rocks: list[PlacedRock]
    rock_textures: RockTextures
    ground: GroundTexture
    board: BoardTexture | None


def place_board(
    rocks: list[PlacedRock], board: BoardTexture, bearing: float, gap: float
) -> BoardTexture:
    """Place ``board`` flat on the ground beyond every rock along ``bearing``, facing the pile.

    The board lies entirely farther along ``bearing`` than any rock vertex: it never touches one.
    """
    u = np.array([np.cos(bearing), np.sin(bearing)])
    reach = max(float((r.mesh.vertices[:, :2] @ u).max()) for r in rocks) if rocks else 0.0
    w, h = board.size()
    # Board x runs across the bearing; the board's y (rows) then points away from the pile.
    yaw = bearing - np.pi / 2
    ex = np.array([np.cos(yaw), np.sin(yaw)])
    ey = np.array([np.sin(yaw), -np.cos(yaw)])
    near = reach + gap + board.margin
    # Origin = top-left corner: centred across the bearing, the pattern starting `near` out.
    start = u * near - ex * (w / 2) if float(ey @ u) > 0 else u * (near + h) - ex * (w / 2)
    return BoardTexture(
        squares_x=board.squares_x,
        squares_y=board.squares_y,
        square_length=board.square_length,
        marker_length=board.marker_length,
        dictionary=board.dictionary,
        origin=(float(start[0]), float(start[1])),
        yaw=float(yaw),
        margin=board.margin,
        px_per_m=board.px_per_m,
    )


def build_scene(seed: int, cfg: SceneConfig) -> Scene:
    """Build the scene of ``seed``; the pile, textures and board draw from separate streams.

    Separate streams keep a pile identical when only its textures' parameters change.
    """
    pile_seq, texture_seq, ground_seq = np.random.SeedSequence(seed).spawn(3)
    rocks = build_pile(np.random.default_rng(pile_seq), cfg.pile)
    textures = RockTextures(np.random.default_rng(texture_seq), len(rocks))
    ground = GroundTexture(np.random.default_rng(ground_seq), size=cfg.ground_px)
    board = place_board(rocks, cfg.board, cfg.board_bearing, cfg.board_gap) if cfg.target else None
    return Scene(rocks=rocks, rock_textures=textures, ground=ground, board=board)
