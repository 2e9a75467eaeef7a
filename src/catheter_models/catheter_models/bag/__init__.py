"""Bag I/O of the science core: record, build, load, repair and describe rosbag2 MCAP bags.

One import for callers (the recorder node, the CLI, analysis scripts); each job lives in its own
module:

* ``writer``   - ``BagRecorder`` (streaming recorder core)
* ``write_failure`` - ``WriteFailure``, ``BagWriteError``, ``CloseOutcome``: a write that failed
* ``from_arrays`` - ``write_bag_from_arrays``: a contract bag from sampled arrays
* ``reader``   - ``load_bag``: a bag's file -> ``BagData``
* ``series``   - ``BagData``, ``StampedSeries``; ``BagData.aligned`` -> ``AlignedSeries``
* ``playback`` - ``Player``: a bag's messages back onto the graph at their recorded pace
* ``repair``   - ``repair_bag`` for truncated or damaged bags, saying what was lost
* ``info``     - ``bag_info`` text summary (``inspect_bag``: with whether it found a problem)
* ``plausible``- the plausibility check of a bag's data (values, stamps, non-finite share)
* ``verify``   - reading an MCAP file past damage: truncated, corrupt, unverifiable, lost
* ``metadata`` - ``metadata.yaml``, QoS profiles, bag layout on disk
* ``messages`` - contract messages <-> SI values
* ``scan``     - front-to-back MCAP reading up to a truncation
"""

from __future__ import annotations

from catheter_models.bag.from_arrays import write_bag_from_arrays
from catheter_models.bag.info import bag_info
from catheter_models.bag.metadata import LATCHED_QOS, SENSOR_DATA_QOS, STREAM_QOS, QosProfile
from catheter_models.bag.reader import load_bag
from catheter_models.bag.repair import RepairReport, repair_bag
from catheter_models.bag.series import AlignedSeries, BagData, StampedSeries
from catheter_models.bag.writer import BagRecorder, SchemaText

__all__ = [
    "LATCHED_QOS",
    "SENSOR_DATA_QOS",
    "STREAM_QOS",
    "AlignedSeries",
    "BagData",
    "BagRecorder",
    "QosProfile",
    "RepairReport",
    "SchemaText",
    "StampedSeries",
    "bag_info",
    "load_bag",
    "repair_bag",
    "write_bag_from_arrays",
]
