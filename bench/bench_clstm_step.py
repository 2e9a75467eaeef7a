"""c-LSTM per-tick compute: the shipped streaming ONNX stepper vs the thesis's 50-sample window.

Ours: the compensator node runs the shipped c-LSTM (``catheter_control/data/clstm``) through
ONNX Runtime as a *streaming* network: one LSTM cell step per control tick, the hidden and
cell state carried in and out (``stream = model.stream(); stream.step(angle_rad)``, one
intra-op thread, ``catheter_models.models.lstm.session_options``).

Baseline, the thesis's way: at every tick the last 50 samples are run through the network in
torch (batch 1, sequence 50, ``torch.no_grad()``) and the last output is kept, with the
network of the same size and the same weights (mapped from the shipped graph's ONNX
initialisers into ``lstm_train.WindowedNet`` and checked against ONNX Runtime), and with the
thesis's own size, 2 x 128 (random weights: only the time is measured). Each torch row runs
at each ``--torch-threads`` setting. Two more rows separate the two effects: the thesis's
size streamed in ONNX Runtime (like for like in size) and the shipped weights windowed in
ONNX Runtime (like for like in framework).

Every step is timed with ``time.perf_counter_ns`` on a realistic input (the desired angle of
``traj_descending_sine`` at the model's rate, repeated), after an untimed warm-up. The rows
take turns, 1,000 steps at a time, so a slow spell of a shared machine hits them all alike
(on this VM one stepper's speed drifted by 2x over a minute); the rows with more than one
torch thread come last, among themselves, since their OpenMP pool slows whatever runs
beside it, and they get a quarter of the steps (their steps take milliseconds here). Targets
(the issue): ours p99 <= 0.2 ms and >= 10x faster (p50 and p99) than the windowed torch
baseline of the same size at its fastest thread setting.

    .venv/bin/python bench/bench_clstm_step.py                # 20,000 steps a row, ~35 s
    .venv/bin/python bench/bench_clstm_step.py --quick        # smoke run, 2,000 steps a row
    .venv/bin/python bench/bench_clstm_step.py --steps 50000 --torch-threads 1

Writes ``bench/results/clstm_step.json`` (``--quick``: ``clstm_step.quick.json``, so a smoke
run never overwrites the documented figures).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import onnx
import torch
from bench_plant import _machine
from onnx import numpy_helper
from tqdm import tqdm

from catheter_control.models import shipped_model_dir
from catheter_models.models import load_model
from catheter_models.models.base import MinMaxScaler, Stream
from catheter_models.models.lstm import (
    INPUT_NAME,
    OUTPUT_NAME,
    STATE_INPUTS,
    CLSTMModel,
    Form,
    GraphSpec,
    rest_state,
    session_options,
)
from catheter_models.models.lstm_train import StreamingNet, WindowedNet, export_onnx
from catheter_models.onnx_runtime import ort
from catheter_models.signals import get_preset
from catheter_ros.rt_loop import DEFAULT_RT_PRIORITY, set_realtime

RESULTS_DIR = Path(__file__).resolve().parent / "results"
RESULTS = RESULTS_DIR / "clstm_step.json"
QUICK_RESULTS = RESULTS_DIR / "clstm_step.quick.json"
PRESET = "traj_descending_sine"
STEPS = 20_000
QUICK_STEPS = 2_000
WARMUP_STEPS = 2_000
"""Untimed steps of each stepper before its first timed block."""
BLOCK_STEPS = 1_000
"""Timed steps a row gets in turn: the rows are interleaved block by block."""
REWARM_STEPS = 10
"""Untimed steps before each block (the previous block ran another row, or torch's threads)."""
THREADED_SHARE = 4
"""Rows with more than one torch thread get 1/THREADED_SHARE of the steps and the warm-up:
on 2 shared cores their steps take milliseconds, and their tail is what they show."""
WINDOW_SAMPLES = 50
"""The thesis's window (eq. 7.4)."""
THESIS_HIDDEN = 128
"""The thesis's c-LSTM: 2 x 128."""
TARGET_P99_US = 200.0
TARGET_SPEEDUP = 10.0
WEIGHT_CHECK_TOL = 1e-4
"""Largest |torch - ONNX Runtime| (normalised output) accepted for the mapped weights."""


def default_out(quick: bool) -> Path:
    """Where the results go unless ``--out`` says otherwise."""
    return QUICK_RESULTS if quick else RESULTS


# -- the shipped graph's weights in torch --------------------------------------------------------
def _torch_gates(onnx_gates: npt.NDArray[np.float32], hidden: int) -> torch.Tensor:
    """ONNX's gate blocks (i, o, f, c) back into torch's order (i, f, g, o)."""
    i, o, f, c = (onnx_gates[k * hidden : (k + 1) * hidden] for k in range(4))
    return torch.from_numpy(np.ascontiguousarray(np.concatenate([i, f, c, o])))


def streaming_net_from_onnx(onnx_bytes: bytes, hidden: int, layers: int) -> StreamingNet:
    """The torch network an exported streaming graph was made from, read from its initialisers.

    The TorchScript exporter writes each layer of ``nn.LSTM`` as one ONNX ``LSTM`` node (W, R
    and B = [Wb, Rb] with the gates reordered) and the head as ``MatMul`` + ``Add``.

    Raises:
        ValueError: The graph is not laid out that way.
    """
    graph = onnx.load_from_string(onnx_bytes).graph
    weights = {t.name: numpy_helper.to_array(t) for t in graph.initializer}
    lstm_nodes = [n for n in graph.node if n.op_type == "LSTM"]
    matmuls = [n for n in graph.node if n.op_type == "MatMul" and n.input[1] in weights]
    adds = [n for n in graph.node if n.op_type == "Add" and any(i in weights for i in n.input)]
    if len(lstm_nodes) != layers or len(matmuls) != 1 or len(adds) != 1:
        raise ValueError(
            f"expected {layers} LSTM nodes and one MatMul + Add head, found {len(lstm_nodes)} "
            f"LSTM, {len(matmuls)} MatMul, {len(adds)} Add with initialisers"
        )
    net = StreamingNet(hidden, layers)
    state: dict[str, torch.Tensor] = {}
    for layer, node in enumerate(lstm_nodes):
        w, r, b = (weights[name][0] for name in node.input[1:4])  # [num_directions = 1, ...]
        state[f"weight_ih_l{layer}"] = _torch_gates(w, hidden)
        state[f"weight_hh_l{layer}"] = _torch_gates(r, hidden)
        state[f"bias_ih_l{layer}"] = _torch_gates(b[: 4 * hidden], hidden)
        state[f"bias_hh_l{layer}"] = _torch_gates(b[4 * hidden :], hidden)
    net.lstm.load_state_dict(state)
    head_w = weights[matmuls[0].input[1]]  # [hidden, 1]
    head_b = next(weights[i] for i in adds[0].input if i in weights)
    net.head.load_state_dict(
        {
            "weight": torch.from_numpy(np.array(head_w.T)),  # copies: initialisers are read-only
            "bias": torch.from_numpy(np.array(head_b)),
        }
    )
    return net.eval()


def check_mapped_weights(net: StreamingNet, model: CLSTMModel, values_si: Sequence[float]) -> float:
    """Largest |torch - ONNX Runtime| of the normalised output over ``values_si`` from rest."""
    session = ort.InferenceSession(
        model.onnx_model_, sess_options=session_options(), providers=["CPUExecutionProvider"]
    )
    spec = _spec(model, "streaming", net.hidden_size)
    h0, c0 = rest_state(session, spec)
    x = model.input_scaler_.transform(np.asarray(values_si)).astype(np.float32).reshape(-1, 1, 1)
    (y_ort,) = session.run([OUTPUT_NAME], {INPUT_NAME: x, STATE_INPUTS[0]: h0, STATE_INPUTS[1]: c0})
    with torch.no_grad():
        y_torch, _, _ = net(torch.from_numpy(x), torch.from_numpy(h0), torch.from_numpy(c0))
    return float(np.max(np.abs(y_torch.numpy() - np.asarray(y_ort))))


def _spec(model: CLSTMModel, form: Form, hidden: int) -> GraphSpec:
    """The spec of the shipped model's kind, scalers and depth, in ``form`` with ``hidden``."""
    return GraphSpec(
        kind=model.kind,
        form=form,
        hidden_size=hidden,
        num_layers=model.config.num_layers,
        window_samples=WINDOW_SAMPLES,
        preview_samples=model.config.preview_samples,
        input_scaler=model.input_scaler_,
        output_scaler=model.output_scaler_,
    )


def ort_stream(net: StreamingNet | WindowedNet, model: CLSTMModel, form: Form) -> Stream:
    """``net`` exported as the shipped model's kind and scalers, stepped as the node steps it."""
    spec = _spec(model, form, net.hidden_size)
    return CLSTMModel.from_graph(export_onnx(net, spec), model.fitted_rate_hz).stream()


# -- the thesis's windowed torch stepper ---------------------------------------------------------
class TorchWindowedStepper:
    """The thesis's tick in torch: the last ``window`` inputs through the network, last output.

    Mirrors ``catheter_models.models.lstm._WindowedStepper`` (eq. 7.9 normalisation, a ring
    buffer left-padded with the input at rest, no allocation but the tensors torch makes), with
    torch in place of ONNX Runtime.
    """

    def __init__(
        self, net: WindowedNet, x_scaler: MinMaxScaler, y_scaler: MinMaxScaler, window: int
    ) -> None:
        self._net = net.eval()
        self._n = window
        self._in_lo, self._in_hi = float(x_scaler.lo), float(x_scaler.hi)
        self._out_lo, self._out_hi = float(y_scaler.lo), float(y_scaler.hi)
        self._rest = float(x_scaler.transform(0.0))
        self._buffer = np.empty(2 * window, dtype=np.float32)
        self.reset()

    def reset(self) -> None:
        """Fill the window with the input at rest."""
        self._buffer[:] = self._rest
        self._pos = 0

    def step(self, value: float) -> float:
        """Input sample in SI, output sample in SI."""
        x = np.float32(2.0 * (value - self._in_lo) / (self._in_hi - self._in_lo) - 1.0)
        p = self._pos
        self._buffer[p] = x
        self._buffer[p + self._n] = x
        window = torch.from_numpy(self._buffer[p + 1 : p + 1 + self._n]).view(1, self._n, 1)
        self._pos = (p + 1) % self._n
        with torch.no_grad():
            y = float(self._net(window)[0, 0])
        return (y + 1.0) * 0.5 * (self._out_hi - self._out_lo) + self._out_lo


def _torch_stepper(
    net: WindowedNet, x_scaler: MinMaxScaler, y_scaler: MinMaxScaler
) -> Callable[[], Stream]:
    return lambda: TorchWindowedStepper(net, x_scaler, y_scaler, WINDOW_SAMPLES)


# -- timing --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Row:
    """One stepper's per-step time [us] and what it is."""

    label: str
    role: str
    """``ours``, ``baseline`` (torch, the thesis's way) or ``reference`` (a like-for-like row)."""
    runtime: str
    form: str
    hidden_size: int
    num_layers: int
    weights: str
    threads: int
    steps: int
    p50_us: float
    p99_us: float
    p999_us: float
    max_us: float
    mean_us: float
    p50_ratio_vs_ours: float | None = None
    """This row's p50 over ours (how many times slower)."""
    p99_ratio_vs_ours: float | None = None


def time_steps(step: Callable[[float], float], values: Sequence[float]) -> npt.NDArray[np.float64]:
    """Wall time [us] of each ``step(v)`` over ``values``."""
    times_ns = np.empty(len(values), dtype=np.int64)
    clock = time.perf_counter_ns
    for i, v in enumerate(values):
        t0 = clock()
        step(v)
        times_ns[i] = clock() - t0
    return times_ns / 1e3


BLOCK_REST_S = 0.1
"""Pause after each timed block [s] (see :func:`time_interleaved`)."""


def time_interleaved(
    runners: Sequence[tuple[Stream, int]],
    values: Sequence[float],
    steps: int,
    warmup: int,
    bar: tqdm[Any],
) -> list[npt.NDArray[np.float64]]:
    """Per-step times [us] of each ``(stream, torch_threads)``, measured block by block in turn.

    Each stream is reset and warmed up on ``values[:warmup]``, untimed. Then, round after
    round (the order rotating), each gets the next block of ``BLOCK_STEPS`` timed steps, after
    ``REWARM_STEPS`` untimed ones, with torch's threads set for it. Every stream sees the
    same input. Interleaving spreads any slow spell of a shared machine over all rows alike,
    so the ratios hold even when the absolute numbers drift.
    """
    for stream, threads in runners:
        torch.set_num_threads(threads)
        stream.reset()
        for v in values[:warmup]:
            stream.step(v)
    times: list[list[npt.NDArray[np.float64]]] = [[] for _ in runners]
    cursor = warmup
    for round_, start in enumerate(range(0, steps, BLOCK_STEPS)):
        n = min(BLOCK_STEPS, steps - start)
        block = values[cursor : cursor + REWARM_STEPS + n]
        cursor += REWARM_STEPS + n
        for j in range(len(runners)):
            k = (round_ + j) % len(runners)
            stream, threads = runners[k]
            torch.set_num_threads(threads)
            for v in block[:REWARM_STEPS]:
                stream.step(v)
            times[k].append(time_steps(stream.step, block[REWARM_STEPS:]))
            bar.update(n)
            # A SCHED_FIFO thread that runs 0.95 s of a second is throttled for the rest by
            # the kernel (sched_rt_runtime_us): rest between blocks, as a loop does between
            # ticks, so that no row is charged a 50 ms stall it would never see in the node.
            time.sleep(BLOCK_REST_S)
    return [np.concatenate(t) for t in times]


def summarise(us: npt.NDArray[np.float64], **what: Any) -> Row:
    """The row of one stepper's per-step times [us]."""
    return Row(
        steps=us.size,
        p50_us=float(np.percentile(us, 50)),
        p99_us=float(np.percentile(us, 99)),
        p999_us=float(np.percentile(us, 99.9)),
        max_us=float(us.max()),
        mean_us=float(us.mean()),
        **what,
    )


def _with_ratios(row: Row, ours: Row) -> Row:
    if row.role == "ours":
        return row
    return Row(
        **(
            asdict(row)
            | {
                "p50_ratio_vs_ours": row.p50_us / ours.p50_us,
                "p99_ratio_vs_ours": row.p99_us / ours.p99_us,
            }
        )
    )


def _print_table(rows: Sequence[Row], rate_hz: float) -> None:
    period_us = 1e6 / rate_hz
    print(
        f"\nc-LSTM per-tick compute on {PRESET} at {rate_hz:g} Hz (one tick = {period_us:g} us); "
        "step time [us]"
    )
    header = (
        f"{'row':<50}{'thr':>4}{'steps':>7}{'p50':>9}{'p99':>9}{'p99.9':>9}{'max':>9}"
        f"{'p50/ours':>10}{'p99/ours':>10}"
    )
    print(header + "\n" + "-" * len(header))
    for r in rows:
        ratios = (
            f"{r.p50_ratio_vs_ours:>9.1f}x{r.p99_ratio_vs_ours:>9.1f}x"
            if r.p50_ratio_vs_ours is not None and r.p99_ratio_vs_ours is not None
            else f"{'-':>10}{'-':>10}"
        )
        print(
            f"{r.label:<50}{r.threads:>4}{r.steps:>7}{r.p50_us:>9.1f}{r.p99_us:>9.1f}{r.p999_us:>9.1f}"
            f"{r.max_us:>9.1f}{ratios}"
        )


def _normal_scheduling() -> str:
    """Back to SCHED_OTHER for the calling thread (a no-op where there is no such call)."""
    if hasattr(os, "sched_setscheduler"):
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    return "SCHED_OTHER"


# -- main ----------------------------------------------------------------------------------------
def main(argv: list[str] | None = None) -> int:
    """Run the benchmark, print the table and write the JSON results."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help=f"smoke run: {QUICK_STEPS:,} steps")
    parser.add_argument("--steps", type=int, default=None, help=f"timed steps a row ({STEPS:,})")
    parser.add_argument(
        "--torch-threads",
        type=int,
        nargs="+",
        default=[1, 2],
        help="torch.set_num_threads for the windowed torch rows, one row each (1 2)",
    )
    parser.add_argument(
        "--model", type=Path, default=shipped_model_dir("clstm"), help="c-LSTM model directory"
    )
    parser.add_argument(
        "--out", type=Path, default=None, help="JSON results file (default by --quick)"
    )
    parser.add_argument(
        "--rt-priority",
        type=int,
        default=DEFAULT_RT_PRIORITY,
        help="time the single-threaded rows under SCHED_FIFO at this priority, as the "
        f"compensator's loop runs (default {DEFAULT_RT_PRIORITY}; 0: normal scheduling)",
    )
    args = parser.parse_args(argv)
    steps = args.steps or (QUICK_STEPS if args.quick else STEPS)
    if steps < 1 or min(args.torch_threads) < 1:
        parser.error("--steps and --torch-threads must be >= 1")
    model = load_model(args.model)
    if not isinstance(model, CLSTMModel) or model.config.form != "streaming":
        parser.error(f"{args.model} is not a streaming c-LSTM")
    threads_before = torch.get_num_threads()
    try:
        return run(args, model, steps, argv)
    finally:
        torch.set_num_threads(threads_before)


def run(args: argparse.Namespace, model: CLSTMModel, steps: int, argv: list[str] | None) -> int:
    """The benchmark proper (``main`` parses, and restores torch's thread count after)."""
    out: Path = args.out or default_out(args.quick)
    rate_hz = model.fitted_rate_hz
    hidden, layers = model.config.hidden_size, model.config.num_layers
    trajectory = get_preset(PRESET).generate(rate_hz).values_si

    # The shipped weights in torch, checked against ONNX Runtime over the trajectory.
    torch.set_num_threads(1)
    shipped_streaming = streaming_net_from_onnx(model.onnx_model_, hidden, layers)
    weight_error = check_mapped_weights(shipped_streaming, model, trajectory[:2000].tolist())
    if not weight_error <= WEIGHT_CHECK_TOL:
        raise SystemExit(f"mapped weights disagree with ONNX Runtime by {weight_error:.2e}")
    shipped_windowed = WindowedNet(hidden, layers)
    shipped_windowed.load_state_dict(shipped_streaming.state_dict())
    torch.manual_seed(0)
    thesis_streaming = StreamingNet(THESIS_HIDDEN, layers)
    thesis_windowed = WindowedNet(THESIS_HIDDEN, layers)
    thesis_windowed.load_state_dict(thesis_streaming.state_dict())
    shipped = f"shipped ({args.model.name}, mapped from ONNX)"
    x_scaler, y_scaler = model.input_scaler_, model.output_scaler_
    ort_threads = session_options().intra_op_num_threads

    # (stream factory, row description); ours first.
    plan: list[tuple[Callable[[], Stream], dict[str, Any]]] = [
        (
            model.stream,
            {
                "label": f"ours: ORT streaming {layers}x{hidden} (shipped)",
                "role": "ours",
                "runtime": "onnxruntime",
                "form": "streaming",
                "hidden_size": hidden,
                "weights": f"shipped ({args.model.name})",
            },
        ),
        (
            lambda: ort_stream(thesis_streaming, model, "streaming"),
            {
                "label": f"ORT streaming {layers}x{THESIS_HIDDEN} (thesis size)",
                "role": "reference",
                "runtime": "onnxruntime",
                "form": "streaming",
                "hidden_size": THESIS_HIDDEN,
                "weights": "random (seed 0)",
            },
        ),
        (
            lambda: ort_stream(shipped_windowed, model, "windowed"),
            {
                "label": f"ORT windowed {WINDOW_SAMPLES} {layers}x{hidden} (shipped weights)",
                "role": "reference",
                "runtime": "onnxruntime",
                "form": "windowed",
                "hidden_size": hidden,
                "weights": shipped,
            },
        ),
    ]
    for threads in args.torch_threads:
        for net, size, weights in (
            (shipped_windowed, hidden, shipped),
            (thesis_windowed, THESIS_HIDDEN, "random (seed 0)"),
        ):
            plan.append(
                (
                    _torch_stepper(net, x_scaler, y_scaler),
                    {
                        "label": f"baseline: torch windowed {WINDOW_SAMPLES} {layers}x{size}"
                        + (" (same weights)" if size == hidden else " (thesis size)"),
                        "role": "baseline",
                        "runtime": "torch",
                        "form": "windowed",
                        "hidden_size": size,
                        "weights": weights,
                        "threads": threads,
                    },
                )
            )

    runners: list[tuple[Stream, int]] = []
    for make, what in plan:
        what.setdefault("threads", ort_threads)
        runners.append((make(), what["threads"] if what["runtime"] == "torch" else 1))
    n_values = WARMUP_STEPS + steps + REWARM_STEPS * -(-steps // BLOCK_STEPS)
    values = [float(v) for v in np.resize(trajectory, n_values)]
    times: dict[int, npt.NDArray[np.float64]] = {}
    threaded_steps = max(1, steps // THREADED_SHARE)
    total = sum(steps if t == 1 else threaded_steps for _, t in runners)
    scheduling: dict[int, str] = {}
    with tqdm(total=total, desc="steps", unit="step", unit_scale=True) as bar:
        # Single-threaded rows first and among themselves: a torch OpenMP pool that has run
        # beside a single-threaded stepper slows it (here ours' p99 went from ~50 to ~500 us).
        for threads in sorted({t for _, t in runners}):
            group = [k for k, (_, t) in enumerate(runners) if t == threads]
            # Every row alike: the node's loop thread is SCHED_FIFO, so single-threaded rows
            # run so too. Never a torch OpenMP pool: its spinning workers would inherit it.
            scheduling[threads] = (
                set_realtime(args.rt_priority) or f"SCHED_FIFO {args.rt_priority}"
                if threads == 1
                else _normal_scheduling()
            )
            n, warmup = (
                (steps, WARMUP_STEPS)
                if threads == 1
                else (threaded_steps, WARMUP_STEPS // THREADED_SHARE)
            )
            measured = time_interleaved([runners[k] for k in group], values, n, warmup, bar)
            times.update(zip(group, measured, strict=True))
    _normal_scheduling()
    rows = [summarise(times[k], num_layers=layers, **what) for k, (_, what) in enumerate(plan)]
    ours = rows[0]
    rows = [_with_ratios(r, ours) for r in rows]
    _print_table(rows, rate_hz)

    same_size = [r for r in rows if r.role == "baseline" and r.hidden_size == hidden]
    fastest = min(same_size, key=lambda r: r.p50_us)
    p50_ratio, p99_ratio = fastest.p50_us / ours.p50_us, fastest.p99_us / ours.p99_us
    p99_met = ours.p99_us <= TARGET_P99_US
    p50_speed_met, p99_speed_met = p50_ratio >= TARGET_SPEEDUP, p99_ratio >= TARGET_SPEEDUP
    targets = {
        "p99_le_200us": {
            "ours_p99_us": ours.p99_us,
            "target_us": TARGET_P99_US,
            "met": p99_met,
        },
        "speedup_ge_10x": {
            "baseline": fastest.label,
            "baseline_threads": fastest.threads,
            "p50_ratio": p50_ratio,
            "p99_ratio": p99_ratio,
            "target": TARGET_SPEEDUP,
            "p50_met": p50_speed_met,
            "p99_met": p99_speed_met,
            "met": p50_speed_met and p99_speed_met,
        },
    }
    print(
        f"\ntarget ours p99 <= {TARGET_P99_US:g} us: {ours.p99_us:.1f} us, "
        f"{'met' if p99_met else 'NOT met'}"
    )
    print(
        f"target >= {TARGET_SPEEDUP:g}x faster than the windowed torch baseline (same weights, "
        f"fastest at {fastest.threads} thread(s)): p50 {p50_ratio:.1f}x "
        f"{'met' if p50_speed_met else 'NOT met'}, p99 {p99_ratio:.1f}x "
        f"{'met' if p99_speed_met else 'NOT met'}"
    )
    print(f"mapped weights: max |torch - ORT| = {weight_error:.1e} (normalised output)")

    payload = {
        "benchmark": "c-LSTM per-tick compute: streaming ONNX vs the thesis's 50-sample window",
        "command": " ".join(
            ["python", "bench/bench_clstm_step.py", *(sys.argv[1:] if argv is None else argv)]
        ),
        "quick": args.quick,
        "input": {
            "preset": PRESET,
            "rate_hz": rate_hz,
            "timed_steps": steps,
            "timed_steps_multithreaded_torch": threaded_steps,
            "warmup_steps": WARMUP_STEPS,
            "block_steps": BLOCK_STEPS,
            "rewarm_steps": REWARM_STEPS,
            "order": (
                "rows interleaved in blocks, the order rotating each round; rows with more "
                "than one torch thread after the others, among themselves"
            ),
            "timer": "time.perf_counter_ns around each step() call; garbage collector on",
        },
        "model": {
            "dir": str(args.model),
            "hidden_size": hidden,
            "num_layers": layers,
            "preview_samples": model.preview_samples,
        },
        "weights_check": {
            "what": "torch with the mapped weights vs ONNX Runtime, streaming, from rest, "
            "normalised output",
            "max_abs_diff": weight_error,
            "samples": 2000,
        },
        "rows": [asdict(r) for r in rows],
        "targets": targets,
        "machine": _machine()
        | {
            "onnxruntime": ort.__version__,
            "torch": torch.__version__,
            "onnx": onnx.__version__,
            "ort_intra_op_threads": str(ort_threads),
            "torch_threads": " ".join(map(str, args.torch_threads)),
            "scheduling": {f"{t} thread(s)": v for t, v in scheduling.items()},
        },
        "unix_time_s": time.time(),
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(payload, indent=2) + "\n")
    print(f"\nwrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
