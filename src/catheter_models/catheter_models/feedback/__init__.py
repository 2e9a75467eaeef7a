"""Closed loop on the measured bend: the feedback law, and gains tuned from recorded steps.

:mod:`.law` holds the law (:class:`FeedbackGains`, :class:`PIDFeedback`, :class:`ClosedLoop`),
which the compensator node runs; :mod:`.tune` identifies the loop and designs the gains;
:mod:`.seal` seals a gains file and checks it against its tuning and the safety envelope, and
:mod:`.reseal` keeps a deliberate edit after re-checking it.
"""

from catheter_models.feedback.law import (
    GAINS_FILE,
    ClosedLoop,
    FeedbackGains,
    PIDFeedback,
)

__all__ = ["GAINS_FILE", "ClosedLoop", "FeedbackGains", "PIDFeedback"]
