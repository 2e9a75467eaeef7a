"""``recorder``: write the contract's topics to an MCAP rosbag2 bag, and say what it lost.

Messages are taken raw (serialized CDR) and written as they came, stamped with receive time as
log time; the header stamps inside carry the time each value was true. The writer closes a
chunk and flushes every ``flush_period_s``, so a killed recorder leaves a bag that
``catheter-lab bag repair`` recovers up to its last chunk.

Intake never waits for the disk: the subscription callbacks only queue the message, and a
writer thread drains the queue into the bag, so a slow flush cannot fill a subscription's
queue. The subscriptions ask for reliable delivery (``qos.RECORD``) from the streams'
reliable publishers, and the node spins rclpy's EventsExecutor (a quarter of the CPU per
message). Whatever is lost anyway (a best-effort publisher over a lossy link, a queue overrun)
shows as a gap in the header stamps: counted per topic (``catheter_models.gaps``), reported
on ``/diagnostics`` and written into the bag's ``custom_data`` (``samples_lost``, ``gaps``).

The intake queue is bounded (``max_queue``): a writer that falls far behind (a busy machine,
a slow disk) makes the recorder drop and count, not grow until the machine swaps. On a stop
the writer goes on for ``close_timeout_s`` at most, so the bag is always finished with its
summary before a launcher's SIGKILL; what it could not write is counted as lost
(``dropped_by_recorder`` in ``custom_data``).

A writer that cannot write (the disk is full, an I/O error, any exception in the writer
thread) stops recording at once, and the graph sees it at once: the recorder publishes
``/diagnostics`` ERROR right then (and every second after) with the reason (the OS's error,
its errno name, the file, when), ``state: failed``, until when the bag holds data
(``recorded_until_ns``) and whether the file is ``finished`` or ``repairable``. The bag is
closed there and then: after a failed write the file is cut back to its last complete flush
(``catheter-lab bag repair`` recovers it; see ``catheter_models.bag.writer``), after any other
error it is finished. From then on every message that arrives is counted per topic as not
written (``not_written``, and in ``lost``), never queued. The recorder is not a lifecycle node
(it starts first and stops last so the bag spans the graph's whole life), so ``failed`` is
its state on /diagnostics; it stays up to keep saying so, and ``follow_trajectory`` and
``commission`` stop their run on it.
"""

from __future__ import annotations

import datetime as dt
import json
import threading
from collections import deque
from pathlib import Path
from typing import Any

from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription

from catheter_models import __version__
from catheter_models.bag import LATCHED_QOS, STREAM_QOS, BagRecorder
from catheter_models.bag.write_failure import BagWriteError, CloseOutcome, WriteFailure
from catheter_models.contract import RECORDED_TOPICS, TRAJECTORY, TopicSpec
from catheter_models.errors import ParameterError
from catheter_models.gaps import StreamGaps, header_stamp_ns, pauses_between_runs
from catheter_models.units import NS_PER_S
from catheter_ros import diagnostics, qos
from catheter_ros.messages import message_class
from catheter_ros.node_main import run_node_as_main
from catheter_ros.params import declare_plain
from catheter_ros.rt_loop import set_process_realtime

RECORDER_RT_PRIORITY = 0
"""Normal scheduling by default: since the drivers take commands in their loop, the recorder at
normal priority keeps every sample at 1 kHz on 2 cores beside two busy loops. Before that,
normal scheduling lost a third at 1 kHz and 10 (below the loops at 50 and their nodes' other
threads at 20, above every normal process) was needed, at the cost of 4.3 % missed deadlines
instead of 1.2 %; the default favours control. See docs/interfaces.md."""

_DRAIN_S = 0.005
"""How often the writer thread looks for queued messages [s] (cheaper than a wake-up each)."""

MAX_QUEUE = 100_000
"""Messages the intake may hold for the writer: 20 s of the whole contract at 1 kHz (5,000
messages/s, about 100 B each, so about 10 MB). Beyond it a message is dropped and counted,
rather than the recorder growing until the machine swaps (measured at 1 kHz beside two busy
loops, before the drivers took commands in their loop: most of a 60 s run was still queued
when the graph stopped)."""

_MAX_DROPPED_STAMPS = 100_000
"""Stamps of dropped samples kept for the gap count between writer passes (about 10 MB)."""

CLOSE_TIMEOUT_S = 6.0
"""How long a stopping recorder goes on writing its backlog [s], below the launcher's 10 s
before SIGKILL: a bag cut off by a kill has no summary, a bag closed with a count of what it
could not write is whole and says so."""


class RecorderNode(Node):
    """Thin ROS shell over :class:`BagRecorder`, with a non-blocking intake and gap counts."""

    def __init__(self) -> None:
        super().__init__("recorder")
        bag_path = str(
            declare_plain(self, "bag_path", "", "bag directory to create (must not exist)")
        )
        if not bag_path:
            raise ParameterError("recorder: parameter bag_path is required (a new directory)")
        custom = json.loads(
            str(declare_plain(self, "custom_data", "{}", "experiment metadata as a JSON object"))
        )
        flush_period_s = float(
            declare_plain(self, "flush_period_s", 0.5, "close a chunk and flush this often [s]")
        )
        compression = str(
            declare_plain(self, "compression", "none", "MCAP chunk compression: none, zstd or lz4")
        )
        custom.setdefault("software_version", __version__)
        custom.setdefault("recorder", self.get_fully_qualified_name())
        self.bag_path = Path(bag_path)
        self.writer = BagRecorder(
            self.bag_path,
            custom_data={k: str(v) for k, v in custom.items()},
            flush_period_s=flush_period_s,
            compression=compression,  # type: ignore[arg-type]
        )
        self.counts: dict[str, int] = {}
        self.gaps: dict[str, StreamGaps] = {}
        self._queue: deque[tuple[str, bytes, int, int]] = deque()
        """Messages for the writer: topic, serialised message, receive time [ns], arrival."""
        self._arrived = 0
        """Messages taken in so far (numbered in arrival order; one intake thread)."""
        self.queue_max = 0
        """The deepest the intake queue has been (messages waiting for the writer thread)."""
        self.max_queue = int(
            declare_plain(
                self, "max_queue", MAX_QUEUE, "messages held for the writer before dropping"
            )
        )
        self.close_timeout_s = float(
            declare_plain(
                self, "close_timeout_s", CLOSE_TIMEOUT_S, "write the backlog this long on stop [s]"
            )
        )
        if self.max_queue < 1 or not self.close_timeout_s > 0.0:
            raise ParameterError(
                f"recorder: max_queue must be >= 1 and close_timeout_s > 0 "
                f"(got {self.max_queue}, {self.close_timeout_s})"
            )
        self.dropped: dict[str, int] = {}
        """Per topic: messages received but not written: dropped at intake (queue full) or
        left unwritten at shutdown. Their stamps still reach the gap count, so a sample is
        counted lost once: as a gap if it never arrived, as dropped if it did."""
        self._dropped_stamps: deque[tuple[str, int | None, int]] = deque()
        """Dropped at intake: topic, header stamp, arrival number. The gap count takes them
        in arrival order among the written ones: a stamp noted late reads as a gap first."""
        self._intake_open = True
        self.not_written: dict[str, int] = {}
        """Per topic: messages not in the bag after the writer failed: queued or arrived since,
        and written after the last complete flush (cut off with it)."""
        self._writer_stopped = False
        """Set by the writer thread at its failure, first: from then on intake counts."""
        self.failure: WriteFailure | None = None
        """Why the writer stopped (None while it records): set once by the writer thread,
        with ``outcome``, once the bag is closed (a status never says less than both)."""
        self.outcome: CloseOutcome | None = None
        """What the bag file holds after a failure (None before one, or before the close)."""
        self._diag_lock = threading.Lock()
        """The writer thread publishes the failure at once, the timer every second."""
        self._subscriptions_by_topic: dict[str, Subscription[Any]] = {}
        self._specs: dict[str, TopicSpec] = {}
        self._best_effort: set[str] = set()
        for spec in RECORDED_TOPICS:
            self._record(spec)
        self._stop = threading.Event()
        self._give_up = threading.Event()
        self._writer_error: BaseException | None = None
        self._writer_thread = threading.Thread(target=self._write_loop, name="bag_writer")
        self._writer_thread.start()
        self._pub_diag = diagnostics.create_diagnostics_publisher(self)
        self.create_timer(1.0, self._publish_diagnostics)
        priority = int(
            declare_plain(
                self,
                "rt_priority",
                RECORDER_RT_PRIORITY,
                "SCHED_FIFO priority of every recorder thread (0: normal scheduling)",
            )
        )
        # Set below every control loop and its helpers, the recorder yields to control, never
        # to a CPU hog at normal priority (a browser, a training job).
        refused = set_process_realtime(priority, background_offset=0) if priority else ""
        self.realtime = refused or (f"SCHED_FIFO {priority}" if priority else "off")
        if refused:
            self.get_logger().warning(f"real-time scheduling {refused}")
        self.get_logger().info(f"recording to {self.bag_path}")

    # -- intake (executor thread): queue and return ---------------------------------------
    def _record(self, spec: TopicSpec) -> None:
        # The bag names topics as they were on the wire, namespace and remapping applied.
        topic = self.resolve_topic_name(spec.name)
        # Offered QoS goes into the bag so that `ros2 bag play` republishes `trajectory`
        # transient-local, as the contract requires, and the streams reliable.
        latched = spec == TRAJECTORY
        self.writer.add_topic(
            topic, spec.msgtype, offered_qos=[LATCHED_QOS if latched else STREAM_QOS]
        )
        self.counts[topic] = 0
        self.dropped[topic] = 0
        self.not_written[topic] = 0
        self._specs[topic] = spec
        if not latched:
            self.gaps[topic] = StreamGaps(pauses=pauses_between_runs(spec.name))
        self._subscribe(topic, qos.TRAJECTORY if latched else qos.RECORD)

    def _subscribe(self, topic: str, profile: QoSProfile) -> None:
        queue = self._queue
        clock = self.get_clock()
        dropped = self.dropped
        dropped_stamps = self._dropped_stamps
        not_written = self.not_written

        def on_message(data: bytes) -> None:
            if not self._intake_open:
                return  # arrived after the stop: not part of the recording
            if self._writer_stopped:
                not_written[topic] += 1  # the writer failed: counted, not queued
                return
            arrival = self._arrived
            self._arrived = arrival + 1
            if len(queue) >= self.max_queue:
                # The writer is far behind: drop and count, never block and never grow
                # without bound. Past _MAX_DROPPED_STAMPS of them (a writer that died) the
                # stamps go unseen too, and the gap count finds those samples instead.
                if len(dropped_stamps) < _MAX_DROPPED_STAMPS:
                    dropped[topic] += 1
                    dropped_stamps.append((topic, header_stamp_ns(data), arrival))
                return
            queue.append((topic, data, clock.now().nanoseconds, arrival))

        spec = self._specs[topic]
        self._subscriptions_by_topic[topic] = self.create_subscription(
            message_class(spec.msgtype), spec.name, on_message, profile, raw=True
        )

    def _adapt_qos(self) -> None:
        """A topic with a best-effort publisher gets a best-effort subscription (said once).

        A reliable subscription does not match a best-effort publisher, so a user's own driver
        publishing with the sensor profile would be recorded as nothing at all.
        """
        for topic, spec in self._specs.items():
            if spec == TRAJECTORY or topic in self._best_effort:
                continue
            offered = self.get_publishers_info_by_topic(topic)
            if any(i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for i in offered):
                self.destroy_subscription(self._subscriptions_by_topic.pop(topic))
                self._subscribe(topic, qos.KEEP_EVERY_SAMPLE)
                self._best_effort.add(topic)
                self.get_logger().warning(
                    f"{topic}: a publisher offers best effort only; recording it best effort, "
                    "so samples lost on the way are not re-sent (they are counted as gaps)"
                )

    # -- writing (writer thread) ----------------------------------------------------------
    def _write_loop(self) -> None:
        try:
            while True:
                stopping = self._stop.is_set()
                self._drain()
                if stopping:
                    return
                self._stop.wait(_DRAIN_S)
        except BaseException as exc:  # any error: stop, close the bag, say so
            try:
                self._writer_failed(exc)
            finally:
                # After: a status in between would say ERROR without what the bag holds.
                self._writer_error = exc

    def _writer_failed(self, exc: BaseException) -> None:
        """Stop recording: count what is left, close the bag, say why at once (writer thread).

        The bag is closed here, not at shutdown: what was written must be readable however
        the process ends, and a writer that failed once cannot be trusted with more.
        """
        writer = self.writer
        if isinstance(exc, BagWriteError):
            failure = exc.failure
        else:
            failure = writer.failure or WriteFailure.of(writer.mcap_path, "write", exc)
        self._writer_stopped = True  # from here intake counts, never queues
        while self._queue:
            topic, _data, _now_ns, _arrival = self._queue.popleft()
            self.not_written[topic] += 1
        self._note_dropped()
        writer.set_custom_data("recording_failed", failure.describe())
        self._store_losses(failure)
        outcome = writer.close()
        for topic, kept in outcome.per_topic.items():
            # Written after the last complete flush, then cut off with the half-written chunk.
            cut = self.counts.get(topic, 0) - kept
            if cut > 0:
                self.counts[topic] -= cut
                self.not_written[topic] += cut
        self.outcome = outcome
        self.failure = failure  # with the outcome: the status says both at once
        log = self.get_logger()
        if not isinstance(exc, BagWriteError | OSError):
            log.error(f"bag writer thread died: {exc!r}")  # a bug: its type says where
        log.error(self._failure_text())
        try:
            self._publish_status()  # at once; the timer repeats it every second
        except Exception as publish_error:  # a context going down at shutdown
            log.warning(f"could not publish the failure on /diagnostics: {publish_error!r}")

    def _failure_text(self) -> str:
        """One line: why the recorder stopped, what the file holds, what it did not write."""
        failure, outcome = self.failure, self.outcome
        if failure is None:
            return ""
        text = f"not recording: {failure.describe()}"
        if outcome is not None:
            text += f"; {outcome.note}"
        unwritten = sum(self.not_written.values())
        return text + f"; {unwritten} messages since not written"

    def _drain(self) -> None:
        queue = self._queue
        self.queue_max = max(self.queue_max, len(queue))
        while not self._give_up.is_set():  # after a give-up, close() counts what is left
            # Read before looking at the queue: whatever arrives later is numbered from here.
            horizon = self._arrived
            if not queue:
                self._note_dropped(before=horizon)
                return
            topic, data, now_ns, arrival = queue.popleft()
            self._note_dropped(before=arrival)
            self.writer.write(topic, data, now_ns, now_ns)
            self.counts[topic] += 1
            self._note_stamp(topic, header_stamp_ns(data))

    def _note_stamp(self, topic: str, stamp_ns: int | None) -> None:
        """A sample of ``topic`` arrived: the gap count must not count it lost."""
        gaps = self.gaps.get(topic)
        if gaps is not None and stamp_ns is not None:
            gaps.add(stamp_ns)

    def _note_dropped(self, before: int | None = None) -> None:
        """Stamps of samples dropped at intake that arrived ``before`` (default: all).

        Writer thread, or close once it stopped. In arrival order with the written ones: a
        burst's dropped stamps noted after later written ones read as gaps first, and the
        gap count could take back only one of them (seen under load: 546 counted lost for
        389 dropped, and nothing else lost).
        """
        dropped = self._dropped_stamps
        while dropped and (before is None or dropped[0][2] < before):
            topic, stamp_ns, _arrival = dropped.popleft()
            self._note_stamp(topic, stamp_ns)

    # -- reporting ------------------------------------------------------------------------
    def loss_summary(self) -> dict[str, dict[str, Any]]:
        """Per topic: samples written, samples lost, gaps, longest gap [s], learned period.

        ``lost`` is what never arrived (gaps in the stamps of every sample received) plus
        what arrived and the recorder could not write (``dropped_by_recorder``).
        """
        return {
            topic: {
                "samples": self.counts[topic],
                "lost": g.lost + self.dropped[topic] + self.not_written[topic],
                "dropped_by_recorder": self.dropped[topic],
                "not_written": self.not_written[topic],
                "gaps": g.gap_count,
                "longest_gap_s": round(g.longest_s, 4),
                "period_s": None if g.period_s is None else round(g.period_s, 6),
            }
            for topic, g in self.gaps.items()
        }

    def _store_losses(self, failure: WriteFailure | None = None) -> None:
        summary = self.loss_summary()
        self.writer.set_custom_data(
            "samples_lost", json.dumps({t: s["lost"] for t, s in summary.items()})
        )
        self.writer.set_custom_data("gaps", json.dumps({t: s["gaps"] for t, s in summary.items()}))
        self.writer.set_custom_data(
            "dropped_by_recorder", json.dumps({t: n for t, n in self.dropped.items() if n})
        )
        if failure is not None or self.failure is not None:
            self.writer.set_custom_data(
                "not_written", json.dumps({t: n for t, n in self.not_written.items() if n})
            )

    def _publish_diagnostics(self) -> None:
        self._adapt_qos()
        if not self.writer.closed:
            self._store_losses()
        self._publish_status()

    def _publish_status(self) -> None:
        """The recorder's /diagnostics status (executor thread, or the writer's at a failure)."""
        with self._diag_lock:
            level, message, values = self.status()
            diagnostics.publish_status(
                self._pub_diag, self, level=level, message=message, values=values
            )

    def status(self) -> tuple[bytes, str, dict[str, object]]:
        """Level, message and values of the recorder's /diagnostics status."""
        values: dict[str, object] = {"bag_path": str(self.bag_path)}
        values["state"] = "recording" if self.failure is None else "failed"
        values.update({f"count {t}": n for t, n in self.counts.items()})
        lost = {t: g.lost + self.dropped[t] + self.not_written[t] for t, g in self.gaps.items()}
        values.update({f"lost {t}": n for t, n in lost.items()})
        values.update({f"gaps {t}": g.gap_count for t, g in self.gaps.items()})
        values.update({f"dropped {t}": n for t, n in self.dropped.items() if n})
        values["queue"] = len(self._queue)
        values["queue_max"] = self.queue_max
        values["realtime"] = self.realtime
        values["best_effort_topics"] = ", ".join(sorted(self._best_effort))
        # Matched publishers per topic: a tool about to start a run waits until the recorder
        # hears every publisher, or the bag would miss the run's start (discovery takes seconds).
        values.update(
            {
                f"publishers {t}": s.get_publisher_count()
                for t, s in self._subscriptions_by_topic.items()
            }
        )
        level, message = diagnostics.OK, "recording"
        failure, outcome = self.failure, self.outcome
        if failure is not None:
            level, message = diagnostics.ERROR, self._failure_text()
            values["error"] = failure.reason
            values["errno"] = failure.errno_name
            values["failed_path"] = str(failure.path)
            values["failed_at_ns"] = failure.at_ns
            values["failed_at"] = dt.datetime.fromtimestamp(failure.at_ns / NS_PER_S).isoformat(
                timespec="milliseconds"
            )
            values.update({f"not_written {t}": n for t, n in self.not_written.items()})
            if outcome is not None:
                values["bag_file"] = "finished" if outcome.finished else "repairable"
                values["recorded_until_ns"] = outcome.until_ns or ""
                values["messages_kept"] = outcome.messages
        elif self._writer_error is not None:
            level, message = diagnostics.ERROR, f"bag writer died: {self._writer_error!r}"
        elif any(lost.values()):
            level = diagnostics.WARN
            message = "recording; lost " + ", ".join(f"{n} of {t}" for t, n in lost.items() if n)
        return level, message, values

    def close(self) -> None:
        """Finish the bag (idempotent), with what it could not write counted.

        Writes what is queued for up to ``close_timeout_s``, counts the rest as lost, stores
        the loss counts and closes the file.
        """
        self._intake_open = False
        self._stop.set()
        self._writer_thread.join(self.close_timeout_s)
        if self._writer_thread.is_alive():
            self._give_up.set()  # the writer stops after the message in hand
            self._writer_thread.join()
        while self._queue:
            topic, data, _now_ns, arrival = self._queue.popleft()
            self._note_dropped(before=arrival)
            self.dropped[topic] += 1
            self._note_stamp(topic, header_stamp_ns(data))
        self._note_dropped()
        if self.failure is not None:
            # Closed at the failure; said then, and on /diagnostics since.
            self.get_logger().error(self._failure_text())
        if not self.writer.closed:
            self._store_losses()
            lost = {t: s["lost"] for t, s in self.loss_summary().items() if s["lost"]}
            if lost:
                self.get_logger().warning(f"bag {self.bag_path} lacks samples: {lost}")
            dropped = {t: n for t, n in self.dropped.items() if n}
            if dropped:
                self.get_logger().warning(
                    f"the recorder itself dropped {dropped} (queue full, or unwritten "
                    f"{self.close_timeout_s:g} s after the stop)"
                )
        self.writer.close()


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run catheter_control recorder``."""
    run_node_as_main(RecorderNode, args, events_executor=True)


if __name__ == "__main__":
    main()
