"""railfuse for Python: simulate test runs, re-fuse MCAP logs through filter pipelines, score
them, tune a pipeline's noise values, and read any channel as a table.

The work is done by the same Rust code as the ``railfuse`` command (the extension
``railfuse._railfuse``, built with maturin), so ``railfuse.refuse`` writes the same bytes as
``railfuse refuse``. Errors raise :class:`RailfuseError` with the command's one-line message.
Fleets of logs on a Ray cluster: :mod:`railfuse.ray`.
"""

from __future__ import annotations

import io
import json
import os
from typing import Iterable, Mapping, Sequence

from . import _railfuse
from ._railfuse import RailfuseError, __version__

__all__ = [
    "RailfuseError",
    "Tuner",
    "__version__",
    "evaluate",
    "read",
    "refuse",
    "simulate",
    "tune",
]

PathLike = str | os.PathLike
#: A run: one log file, a directory of its parts or a ROS 2 bag, or a list of files (the
#: parts of a split recording, several recorders' files), read as one log.
RunLike = PathLike | Sequence[PathLike]


def _run(run: RunLike) -> list[str]:
    """The files and directories of a run, as the extension takes them."""
    if isinstance(run, (str, os.PathLike)):
        return [os.fspath(run)]
    return [os.fspath(p) for p in run]


def simulate(
    output: PathLike,
    scenario: str = "default",
    seed: int = 0,
    duration_s: float | None = None,
    faults: Iterable[str] = (),
) -> dict:
    """Simulate a test run (truth and every sensor) into the MCAP log ``output``.

    ``faults`` take the command line's form, ``DEVICE:MODE:START:END[:reported]``. Returns the
    report (scenario, seed, duration, messages per topic)."""
    return json.loads(
        _railfuse.simulate(os.fspath(output), scenario, seed, duration_s, list(faults))
    )


def refuse(
    input: RunLike,
    config: PathLike,
    output: PathLike,
    reference: str = "/truth",
    align: str = "none",
    reference_quality: str = "auto",
    withhold: str | None = None,
    outages: str | None = None,
) -> dict:
    """Re-fuse the run ``input`` (a file, a directory of parts, a bag, or a list of files)
    with the pipelines of ``config`` into ``output``, as ``railfuse refuse`` does. Returns
    ``{"refuse": …, "eval": …}``: what each pipeline did, and the accuracy table against
    ``reference``. ``align="gnss"`` puts several recorders' files on one clock through the
    GNSS time each logged (``--align gnss``). ``reference_quality`` says which fixes of a
    GNSS reference count (``--reference-quality``: ``auto``, ``all``, ``rtk_fixed``, …).
    ``withhold`` hides that sensor from the pipelines in ``outages`` (``"60:every=180"``,
    ``"standard"``; the whole run without) and scores against it, as ``--withhold`` and
    ``--outages`` do; the reference is then that sensor unless ``reference`` names another
    than ``"/truth"``."""
    if withhold is not None and reference == "/truth":
        reference = withhold
    return json.loads(
        _railfuse.refuse(
            _run(input),
            os.fspath(config),
            os.fspath(output),
            reference,
            align,
            reference_quality,
            withhold,
            outages,
        )
    )


def evaluate(
    input: RunLike,
    reference: str | None = None,
    align: str = "none",
    reference_quality: str = "auto",
    withhold: str | None = None,
    outages: str | None = None,
) -> dict:
    """The accuracy table of a fused log's pipelines against ``reference`` (ground truth, a
    GNSS channel, another pipeline's state). Without one, the ground truth (``/truth``) where
    the log has it, else NIS and counts only; a reference named that the log does not have,
    or that gives no samples, raises :class:`RailfuseError`, as ``railfuse eval`` fails.
    ``reference_quality`` says which fixes of a GNSS reference count, as
    ``--reference-quality`` does."""
    report = json.loads(
        _railfuse.evaluate(
            _run(input),
            reference or withhold or "/truth",
            align,
            reference_quality,
            withhold,
            outages,
        )
    )
    if reference is not None and report.get("reference") is None:
        raise RailfuseError(
            f"{_run(input)[0]}: reference {reference} is not in the log or gives no samples"
        )
    return report


def read(path: RunLike, topic: str, mapping: str | os.PathLike | None = None):
    """Every message of ``topic`` in the run ``path`` (a file, a directory of parts, a bag,
    or a list of files; a logger's CSV with its column ``mapping``, as ``--map`` takes it)
    as a ``pyarrow.Table``: one row per message, a column per
    field (nested fields as structs and lists), ``log_time_ns`` first. Fused states and
    diagnostics (``/fused/<pipeline>/state``) read like any other channel. For
    ``Table.to_pandas()``, install the ``pandas`` extra: ``pip install 'railfuse[pandas]'``."""
    import pyarrow as pa
    import pyarrow.json as pajson

    lines = _railfuse.read_json_lines(_run(path), topic, os.fspath(mapping) if mapping else None)
    if not lines:
        return pa.table({"log_time_ns": pa.array([], pa.int64())})
    return pajson.read_json(
        io.BytesIO(lines), read_options=pajson.ReadOptions(block_size=1 << 24)
    )


def _param_args(params: Mapping[str, Sequence[float]] | Iterable[str] | None) -> list[str]:
    """``{"motion.jerk_psd": (0.001, 10)}`` or ``["motion.jerk_psd=0.001..10"]`` as the
    command line's ``PATH=MIN..MAX``."""
    if params is None:
        return []
    if isinstance(params, Mapping):
        return [f"{name}={lo!r}..{hi!r}" for name, (lo, hi) in params.items()]
    return list(params)


class Tuner:
    """A tuning run with its logs decoded once: evaluate candidates, or search.

    >>> t = Tuner(["run.mcap"], "samples/kalman.toml", "kalman", reference="/truth",
    ...           params={"motion.jerk_psd": (0.001, 10)})
    >>> t.evaluate([0.05])["objective"]
    """

    def __init__(
        self,
        logs: Iterable[PathLike],
        config: PathLike,
        pipeline: str,
        reference: str | None = None,
        params: Mapping[str, Sequence[float]] | Iterable[str] | None = None,
        objective: str | None = None,
        optimiser: str | None = None,
        max_evaluations: int | None = None,
        seed: int | None = None,
        withhold: str | None = None,
        outages: str | None = None,
    ):
        self.logs = [os.fspath(p) for p in logs]
        self.config = os.fspath(config)
        self.pipeline = pipeline
        self._inner = _railfuse.Tuner(
            self.logs,
            self.config,
            pipeline,
            reference,
            _param_args(params),
            objective,
            optimiser,
            max_evaluations,
            seed,
            withhold,
            outages,
        )

    @property
    def params(self) -> list[dict]:
        """Each tuned value: ``path``, ``min``, ``max``, ``scale``, ``start`` (the file's),
        ``steps`` (grid points), ``integer``."""
        return json.loads(self._inner.params())

    def grid(self) -> list[list[float]]:
        """Per parameter, the points a grid search takes (as the file will hold them)."""
        return json.loads(self._inner.grid())

    def evaluate(self, values: Sequence[float]) -> dict:
        """``{"objective", "metrics", "logs"}`` with ``values``, one per parameter."""
        return json.loads(self._inner.evaluate([float(v) for v in values]))

    def evaluate_log(self, index: int, values: Sequence[float]) -> float:
        """The objective of log ``index`` alone."""
        return self._inner.evaluate_log(index, [float(v) for v in values])

    def tuned_toml(self, values: Sequence[float]) -> str:
        """The configuration text with ``values`` written in, comments kept."""
        return self._inner.tuned_toml([float(v) for v in values])

    def run(self) -> dict:
        """Search; ``{"report", "trace", "tuned_toml"}``."""
        return json.loads(self._inner.run())


def tune(
    logs: Iterable[PathLike],
    config: PathLike,
    pipeline: str,
    output: PathLike | None = None,
    reference: str | None = None,
    params: Mapping[str, Sequence[float]] | Iterable[str] | None = None,
    objective: str | None = None,
    optimiser: str | None = None,
    max_evaluations: int | None = None,
    seed: int | None = None,
    withhold: str | None = None,
    outages: str | None = None,
) -> dict:
    """``railfuse tune`` from Python: search, write the tuned configuration to ``output`` (if
    given) and return ``{"report", "trace", "tuned_toml"}``. ``withhold`` and ``outages``
    tune by cross-validation against a receiver hidden from the pipeline, as ``--withhold``
    and ``--outages`` do."""
    result = Tuner(
        logs,
        config,
        pipeline,
        reference,
        params,
        objective,
        optimiser,
        max_evaluations,
        seed,
        withhold,
        outages,
    ).run()
    if output is not None:
        with open(output, "w") as f:
            f.write(result["tuned_toml"])
    return result
