"""Pictures of games and campaigns: maps and trajectories as PNG (Pillow), a campaign's
results as one HTML page with inline SVG charts.

Layered above the console's colours (`tui.widgets.map_pixels`) and the recording's
reader (`tui.replay.index`); nothing here runs a game. `map_image` draws a grid,
`game_image` draws a recorded game on it, `charts` makes the SVG charts and
`campaign_page` the campaign's page. Import the modules themselves: nothing is
re-exported here, so a command pays only for what it draws (Pillow is imported by
the two PNG modules alone).
"""
