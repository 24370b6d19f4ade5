"""The bench and its leaderboard: one versioned protocol per scenario and track (`bench`, `tracks`), one row per
policy, the leaderboard made from the rows (`leaderboard`, its plots in `leaderboard_plot`), a row's exact check
(`exact_row` writes it, `exact_board` reads it) and the zoo's model cards, made from the zoo runs' bench rows
(`zoo_card`). A row's cells are ordinary grid cells: this room runs and reads them through the grid engine of
`zodrive.experiments` (`compare`, `cells.GridCell`), and its cards are written by that room's one card writer
(`experiments.card`); nothing there imports from here."""
