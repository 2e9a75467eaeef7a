"""Error classes of the science core.

Each names the thing that was wrong and, where it can, what would be right. Callers catch
the narrow class; the message is written for a person at the rig, not for a stack trace.
"""

from __future__ import annotations


class CatheterError(Exception):
    """Base of every error this stack raises on purpose."""


class ParameterError(CatheterError, ValueError):
    """A parameter is out of its range, non-finite, or unknown. The message names the range."""


class SignalError(CatheterError, ValueError):
    """A signal or trajectory cannot be generated or is not physically possible."""


class GraphConflictError(CatheterError):
    """Another graph already runs in the ROS namespace and domain a new one would start in.

    Raised before anything starts where a launcher's look sees it, and by the lifecycle
    manager where only the duplicate node names or their states show it.
    """


class BagError(CatheterError):
    """A bag cannot be read as the interface contract requires."""


class MissingTopicError(BagError):
    """A bag lacks a topic the contract requires. The message names the topic."""


class TruncatedBagError(BagError):
    """A bag's MCAP file ends mid-record (a killed recorder). The message says how to repair it."""
