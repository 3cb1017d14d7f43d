"""The high-level MDP of desk wiping (paper section 4, "High-level goal selector"; A.7, "Details of High
Level").

The wiping area of the desk is cut into square cells of 0.05 m, slightly smaller than the sponge, so a
stroke from one cell centre to the next wipes the cell it lands on. A high-level state s^h is a cell
(col, row); a high-level action a^h is one of four moves. Moving off the grid keeps the state.

U (A.7, Fig. 1) maps (s^h, a^h) to a low-level goal on the desk surface: the centre of the next cell,
through the linear transform

    x = area_x[0] + (col + 1/2) * cell,    y = area_y[0] + (row + 1/2) * cell,

so the grid is aligned with the desk, column 0 at the left edge of the area and row 0 on the robot's side.
The desk height is not part of U: the low-level controller presses at the (estimated) surface itself.

The grid may drift from the world when the low-level policy fails to reach its goal; the state is then
re-aligned to the cell the sponge is really in (A.7).
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

from hipref.validation import check_range

Cell = tuple[int, int]
"""A high-level state: (column along x, row along y)."""

ACTIONS: tuple[str, ...] = ("up", "down", "left", "right")
"""The four high-level actions; "up" moves away from the robot (+y), "right" along +x."""
MOVES: tuple[Cell, ...] = ((0, 1), (0, -1), (-1, 0), (1, 0))
"""(d col, d row) of each action, in the order of `ACTIONS`."""
UP, DOWN, LEFT, RIGHT = range(4)


class WipingGrid:
    """The grid world over the wiping area: transitions, the mapping U, re-alignment and the expert."""

    def __init__(
        self,
        area_x: tuple[float, float] = (-0.3, 0.3),
        area_y: tuple[float, float] = (-0.1, 0.2),
        cell_size: float = 0.05,
    ) -> None:
        """
        Args:
            area_x, area_y: extent of the wiping area on the desk in m (`WipingConfig.area_x/area_y`).
            cell_size: side of a cell in m (A.7: 0.05 m); must tile the area exactly.
        """
        check_range("cell_size", cell_size, 0.01, 0.5)
        self.area_x = (float(area_x[0]), float(area_x[1]))
        self.area_y = (float(area_y[0]), float(area_y[1]))
        self.cell_size = float(cell_size)
        cols = (self.area_x[1] - self.area_x[0]) / cell_size
        rows = (self.area_y[1] - self.area_y[0]) / cell_size
        tiles = abs(cols - round(cols)) < 1e-6 and abs(rows - round(rows)) < 1e-6
        if not tiles or round(cols) < 2 or round(rows) < 2:
            raise ValueError(
                f"cell_size must tile the area into at least 2 x 2 cells, got {cell_size}"
                f" for x {area_x}, y {area_y}"
            )
        self.n_cols = round(cols)
        self.n_rows = round(rows)
        if self.n_rows % 2:
            raise ValueError(f"the coverage expert needs an even number of rows, got {self.n_rows}")

    @property
    def n_states(self) -> int:
        return self.n_cols * self.n_rows

    @property
    def n_actions(self) -> int:
        return len(ACTIONS)

    def cells(self) -> Iterator[Cell]:
        for row in range(self.n_rows):
            for col in range(self.n_cols):
                yield (col, row)

    def index(self, cell: Cell) -> int:
        """The cell as an integer state index (row-major)."""
        return cell[1] * self.n_cols + cell[0]

    def inside(self, cell: Cell) -> bool:
        return 0 <= cell[0] < self.n_cols and 0 <= cell[1] < self.n_rows

    def move(self, state: Cell, action: int) -> Cell:
        """T^h: the next cell; a move off the grid keeps the state."""
        dc, dr = MOVES[action]
        nxt = (state[0] + dc, state[1] + dr)
        return nxt if self.inside(nxt) else state

    def center(self, cell: Cell) -> np.ndarray:
        """The linear grid -> desk transform: the centre of `cell` on the desk plane, in m."""
        return np.array(
            [
                self.area_x[0] + (cell[0] + 0.5) * self.cell_size,
                self.area_y[0] + (cell[1] + 0.5) * self.cell_size,
            ]
        )

    def goal(self, state: Cell, action: int) -> np.ndarray:
        """U(s^h, a^h): the low-level goal on the desk surface, the centre of the next cell."""
        return self.center(self.move(state, action))

    def cell_of(self, xy: np.ndarray) -> Cell | None:
        """The cell containing the desk point `xy`, or None outside the wiping area."""
        col = math.floor((float(xy[0]) - self.area_x[0]) / self.cell_size)
        row = math.floor((float(xy[1]) - self.area_y[0]) / self.cell_size)
        return (col, row) if self.inside((col, row)) else None

    def nearest_cell(self, xy: np.ndarray) -> Cell:
        """The cell containing `xy`, or the closest one when `xy` lies just outside the area."""
        col = math.floor((float(xy[0]) - self.area_x[0]) / self.cell_size)
        row = math.floor((float(xy[1]) - self.area_y[0]) / self.cell_size)
        return (min(max(col, 0), self.n_cols - 1), min(max(row, 0), self.n_rows - 1))

    def realign(self, target: Cell, reached: bool, tool_xy: np.ndarray) -> Cell:
        """The state after a stroke towards `target`: the target when reached; otherwise (A.7) the grid is
        reset to the cell where the sponge really ended, so the abstract state never drifts from the world."""
        return target if reached else self.nearest_cell(tool_xy)

    def wiped(self, tool_xy: np.ndarray, force: np.ndarray, band: tuple[float, float]) -> set[Cell]:
        """The cells wiped over a stretch of control periods: those the sponge's centre passed over while
        pressing with a contact force inside the safe band (hovering or crushing does not clean)."""
        pressing = (force >= band[0]) & (force <= band[1])
        cells = (self.cell_of(xy) for xy in tool_xy[pressing])
        return {cell for cell in cells if cell is not None}

    def expert(self, state: Cell) -> int:
        """The hand-coded coverage expert: a boustrophedon closed into a cycle through every cell.

        Row 0 is swept left to right; rows 1.. snake over columns 1.. (odd rows leftwards, even rows
        rightwards); from the end of the last row column 0 leads back down to the start. The action
        depends on the state only, and following it from any cell visits all cells in n_states - 1 moves,
        so coverage survives a re-alignment that lands the sponge elsewhere.
        """
        col, row = state
        last_col, last_row = self.n_cols - 1, self.n_rows - 1
        if row == 0:
            return UP if col == last_col else RIGHT
        if col == 0:
            return DOWN
        if row % 2:  # sweeping leftwards over columns 1..
            if col > 1:
                return LEFT
            return LEFT if row == last_row else UP
        return UP if col == last_col else RIGHT
