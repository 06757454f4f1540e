"""The rerun viewer's default layout for an exploration recording (``explore.report.recorder``)."""

from __future__ import annotations

from typing import Any

TIMELINES = ("episode", "time")


def default_blueprint(half_width: float, goals: bool = False) -> Any:
    """Viewer layout: arena history and camera on the left, this episode's motion and the goal
    space in the middle, cells and joints on the right; the ``time`` timeline selected and
    following the latest data; the blueprint and selection panels collapsed (the views get the
    room; the buttons at the top right open them).

    Args:
        half_width: of the metric's square (the rig's scene's ``ball_half_width``).
        goals: show the goal-space tab first (the strategy sets goals and their outcomes are
            logged) instead of the 3-D tool tip.
    """
    import rerun.blueprint as rrb

    h = half_width * 1.1
    bounds = rrb.VisualBounds2D(x_range=[-h, h], y_range=[-h, h])
    history = [
        rrb.VisibleTimeRange(
            tl, start=rrb.TimeRangeBoundary.infinite(), end=rrb.TimeRangeBoundary.cursor_relative()
        )
        for tl in TIMELINES
    ]
    recent = rrb.VisibleTimeRange(
        "time",
        start=rrb.TimeRangeBoundary.cursor_relative(seconds=-20.0),
        end=rrb.TimeRangeBoundary.cursor_relative(),
    )
    # the whole run on the x axis (the viewer's default follows the cursor over about a minute)
    whole_run = rrb.TimeAxis(
        view_range=rrb.TimeRange(
            start=rrb.TimeRangeBoundary.infinite(), end=rrb.TimeRangeBoundary.infinite()
        )
    )
    goal_tabs = [
        rrb.Spatial2DView(
            name="Goal vs reached (goal space, this episode)",
            origin="/goal",
            contents=["+ /goal/target", "+ /goal/reached", "+ /goal/miss"],
        ),
        rrb.Spatial2DView(
            name="Reached in goal space (all so far)",
            origin="/goal",
            contents=["+ /goal/reached"],
            time_ranges=history,
        ),
    ]
    motion_tabs = [
        rrb.Spatial3DView(name="Tool tip (3-D)", origin="/arm"),
        rrb.TextLogView(name="Kinds", origin="/strategy"),
    ]
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial2DView(
                    name="Ball outcomes (all episodes so far)",
                    origin="/arena",
                    contents=["+ /arena/bounds", "+ /arena/ball", "+ /arena/ball_track"],
                    visual_bounds=bounds,
                    time_ranges=history,
                ),
                rrb.Spatial2DView(name="Outcome image", origin="/camera"),
            ),
            rrb.Vertical(
                rrb.Spatial2DView(
                    name="This episode: tool tip and ball",
                    origin="/arena",
                    visual_bounds=bounds,
                ),
                rrb.Tabs(*(goal_tabs + motion_tabs if goals else motion_tabs + goal_tabs)),
            ),
            rrb.Vertical(
                rrb.TimeSeriesView(
                    name="Cells reached",
                    origin="/stats",
                    contents=["+ /stats/ball_cells", "+ /stats/ee_cells"],
                    axis_x=whole_run,
                ),
                rrb.TimeSeriesView(
                    name="Joints: target vs measured (rad)", origin="/joints", time_ranges=[recent]
                ),
                rrb.Tabs(
                    rrb.TimeSeriesView(
                        name="Ball moved (fraction)",
                        origin="/stats",
                        contents=["+ /stats/moved_fraction"],
                        axis_x=whole_run,
                    ),
                    rrb.TimeSeriesView(name="Goal error", origin="/goal", axis_x=whole_run),
                    rrb.TimeSeriesView(name="Module", origin="/strategy", axis_x=whole_run),
                    rrb.TimeSeriesView(name="Progress", origin="/progress", axis_x=whole_run),
                    rrb.TimeSeriesView(name="Series", origin="/series", axis_x=whole_run),
                    rrb.Spatial2DView(name="Frames", origin="/frames"),
                ),
            ),
            column_shares=[1.0, 1.0, 1.2],
        ),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline="time", play_state="following"),
    )
