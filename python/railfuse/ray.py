"""railfuse on a Ray cluster, for fleets of logs that outgrow one machine.

- :func:`refuse_many`, :func:`evaluate_many`: one Ray task per log.
- :func:`tune`: a tuning search as a Ray Tune experiment. Each trial is one candidate; it
  replays the logs one by one with railfuse's evaluation and reports the objective summed over
  the logs so far, so a scheduler (ASHA by default) can stop a hopeless candidate after its
  first logs. The grid search takes exactly the points ``railfuse tune --optimiser grid``
  takes, so both find the same values.

Connect first (``ray.init()`` locally, ``ray.init("ray://head:10001")`` on a cluster); every
node needs this package and the logs at the same paths (a shared file system or object store
mount).
"""

from __future__ import annotations

import os
from typing import Iterable, Mapping, Sequence

import ray
from ray import tune as ray_tune

import railfuse


@ray.remote
def _refuse(input: list[str], config: str, output: str, reference: str) -> dict:
    return railfuse.refuse(input, config, output, reference)


@ray.remote
def _evaluate(input: list[str], reference: str | None) -> dict:
    return railfuse.evaluate(input, reference)


def _absolute(run: railfuse.RunLike) -> list[str]:
    """A run's files and directories as absolute paths, for any node of the cluster."""
    return [os.path.abspath(p) for p in railfuse._run(run)]


def refuse_many(
    inputs: Iterable[railfuse.RunLike],
    config: os.PathLike | str,
    outputs: Iterable[os.PathLike | str] | None = None,
    reference: str = "/truth",
) -> list[dict]:
    """Re-fuse every run (a log file, a directory of parts, a bag, or a list of files) as a
    Ray task (outputs default to ``<first input>.fused.mcap``); the reports in input order."""
    inputs = [_absolute(run) for run in inputs]
    if outputs is None:
        outputs = [run[0].rstrip("/").removesuffix(".mcap") + ".fused.mcap" for run in inputs]
    outputs = [os.path.abspath(p) for p in outputs]
    config = os.path.abspath(config)
    return ray.get([_refuse.remote(i, config, o, reference) for i, o in zip(inputs, outputs)])


def evaluate_many(inputs: Iterable[railfuse.RunLike], reference: str | None = None) -> list[dict]:
    """The accuracy table of every fused run, one Ray task each, in input order."""
    return ray.get([_evaluate.remote(_absolute(run), reference) for run in inputs])


def _trial(candidate: dict, *, logs, config, pipeline, reference, params, objective, names):
    """One candidate: the logs replayed one by one, the summed objective reported after each."""
    tuner = railfuse.Tuner(logs, config, pipeline, reference, params, objective)
    values = [candidate[name] for name in names]
    total = 0.0
    for i in range(len(logs)):
        total += tuner.evaluate_log(i, values)
        ray_tune.report({"objective": total, "logs": i + 1})


def _search_space(search: str, local, names: list, num_samples: int) -> tuple[dict, int]:
    """Ray Tune's parameter space and sample count: railfuse's grid, or ``num_samples``
    draws on each parameter's own scale."""
    if search == "grid":
        space = {n: ray_tune.grid_search(points) for n, points in zip(names, local.grid())}
        samples = 1
    elif search == "random":
        space = {
            p["path"]: (ray_tune.loguniform if p["scale"] == "log" else ray_tune.uniform)(
                p["min"], p["max"]
            )
            for p in local.params
        }
        samples = num_samples
    else:
        raise railfuse.RailfuseError(f"ray tune: unknown search '{search}' (grid or random)")
    return space, samples


def _seeded_search(search: str, seed: int):
    """Random search draws its candidates from ``seed``; grid search needs no generator."""
    if search != "random":
        return None
    from ray.tune.search.basic_variant import BasicVariantGenerator

    return BasicVariantGenerator(random_state=seed)


def _best_complete(results, n_logs: int):
    """The best trial of those that evaluated every log (an early-stopped one reports a
    partial sum); a failed trial fails the search with its cause."""
    errors = [r.error for r in results if r.error is not None]
    if errors:
        cause = errors[0]
        while getattr(cause, "cause", None) is not None:
            cause = cause.cause
        raise railfuse.RailfuseError(f"ray tune: a trial failed: {cause}")
    complete = [r for r in results if r.metrics and r.metrics.get("logs") == n_logs]
    if not complete:
        raise railfuse.RailfuseError("ray tune: no trial evaluated every log")
    return min(complete, key=lambda r: r.metrics["objective"])


def tune(
    logs: Iterable[os.PathLike | str],
    config: os.PathLike | str,
    pipeline: str,
    params: Mapping[str, Sequence[float]] | Iterable[str],
    reference: str | None = None,
    objective: str | None = None,
    search: str = "grid",
    num_samples: int = 20,
    early_stopping: bool = True,
    seed: int = 0,
    output: os.PathLike | str | None = None,
    storage_path: os.PathLike | str | None = None,
) -> dict:
    """A tuning search as a Ray Tune experiment over ``logs``.

    ``search``: ``"grid"`` (every point of railfuse's grid, ``steps`` a value) or ``"random"``
    (``num_samples`` candidates drawn on each parameter's scale, seeded). With
    ``early_stopping``, ASHA stops candidates whose summed objective trails after their first
    logs. Returns ``{"values", "objective", "tuned_toml", "trials"}`` and writes the tuned
    configuration to ``output`` if given."""
    # Trials run in folders of their own: paths must not be relative.
    logs = [os.path.abspath(p) for p in logs]
    config = os.path.abspath(config)
    local = railfuse.Tuner(logs, config, pipeline, reference, params, objective)
    meta = local.params
    names = [p["path"] for p in meta]
    space, samples = _search_space(search, local, names, num_samples)
    scheduler = None
    if early_stopping and len(logs) > 1:
        from ray.tune.schedulers import ASHAScheduler

        scheduler = ASHAScheduler(time_attr="logs", max_t=len(logs), grace_period=1)
    trainable = ray_tune.with_parameters(
        _trial,
        logs=logs,
        config=config,
        pipeline=pipeline,
        reference=reference,
        params=railfuse._param_args(params),
        objective=objective,
        names=names,
    )
    run_config = ray_tune.RunConfig(
        name=f"railfuse-tune-{pipeline}",
        storage_path=os.path.abspath(storage_path) if storage_path is not None else None,
        verbose=0,
        # One failed candidate is a failed search (a bad log, a refused value): say why.
        failure_config=ray_tune.FailureConfig(fail_fast=True),
    )
    experiment = ray_tune.Tuner(
        trainable,
        param_space=space,
        tune_config=ray_tune.TuneConfig(
            metric="objective",
            mode="min",
            scheduler=scheduler,
            num_samples=samples,
            search_alg=_seeded_search(search, seed),
        ),
        run_config=run_config,
    )
    results = experiment.fit()
    best = _best_complete(results, len(logs))
    values = [best.config[n] for n in names]
    tuned = local.tuned_toml(values)
    if output is not None:
        with open(output, "w") as f:
            f.write(tuned)
    return {
        "values": dict(zip(names, values)),
        "objective": best.metrics["objective"],
        "tuned_toml": tuned,
        "trials": len(results),
    }
