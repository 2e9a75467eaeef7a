"""The terminal progress bar ``follow_trajectory`` shows while a trajectory runs.

Its own file because it is the one piece of the run that is about the terminal, not about
ROS or the score: it shows the compensator's clock (from the goal's feedback), in tenths of
a second, and only on a terminal.
"""

from __future__ import annotations

from tqdm import tqdm


class ProgressBar:
    """Seconds of the trajectory done, out of its duration.

    Args:
        duration_s: The trajectory's duration [s].
        enabled: False: no bar at all. True: a bar on a terminal only; piped output gets no
            stream of redraws.
    """

    def __init__(self, duration_s: float, enabled: bool) -> None:
        self._duration_s = duration_s
        self._bar = tqdm(
            total=round(duration_s, 1),
            unit="s",
            # None: show on a terminal only; piped output gets no stream of redraws.
            disable=None if enabled else True,
            mininterval=0.5,
            bar_format="{l_bar}{bar}| {n:.1f}/{total:.1f} s",
        )

    def show(self, plan_time_s: float) -> None:
        """Move the bar on to ``plan_time_s`` (the compensator's newest feedback) [s]."""
        done_s = round(min(plan_time_s, self._duration_s), 1)
        if done_s > self._bar.n:
            self._bar.update(done_s - self._bar.n)

    def close(self) -> None:
        """Take the bar down (before anything else is printed)."""
        self._bar.close()
