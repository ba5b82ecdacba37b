"""``iloci sweep``: config values x seeds x folds on Ray, resumable.

A sweep spec is a TOML file::

    base = "my.toml"        # a config file (relative to the spec); default: the defaults
    seeds = [0, 1]          # evaluation seeds (fold split, order, networks); default [0]
    folds = [0, 1, 2]       # folds of each seed's split to run; default all
    search = "grid"         # or "random"
    samples = 8             # random: settings drawn
    random_seed = 0         # random: seed of the draws

    [config]                # fixed changes to the base config
    perceptual_model = { name = "torch-rnnpb", epochs = 2000 }

    [values]                # what is swept: "section.key" = ...
    "learner.k_cutoff" = [0.25, 0.5, 1.0]          # grid: every value; random: one of them
    "learner.num_threshold" = { low = 2, high = 6, integer = true }   # random only
    "perceptual_model.learning_rate" = { low = 1e-3, high = 1e-1, log = true }

A *run* is one fold of one seed of one setting (an assignment of every swept
key). Its metrics are stored in ``OUT/runs/<key>.json`` as soon as it
finishes, ``key`` being a SHA-256 of the resolved config (the base, the
changes, the setting and the seed, every default filled in), the fold and the
seed: a sweep started again with the same spec (or another that shares runs)
skips every run whose file exists. ``OUT/results.csv`` has a row per run,
``OUT/report.md`` the table of settings and figures (:mod:`iloci_ray.report`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
import contextlib
import hashlib
import itertools
import math
import json
import os
from pathlib import Path
import time
from typing import Any

import numpy as np

from iloci.errors import ConfigError, InvalidInputError

__all__ = ["SweepSpec", "Run", "load_spec", "plan_runs", "run_key", "run_sweep",
           "summary_lines", "RUN_METRICS"]

#: Metrics stored per run (from the fold's result; see iloci.evaluation.evaluate).
RUN_METRICS = ("ccr", "feedbacks", "rewarded", "interactions_per_demo", "entries",
               "concepts", "generation_error", "wall_seconds")
#: Also stored per run when ``dtaidistance`` (the ``report`` extra) is installed:
#: ``baselines``, name -> CCR of each baseline of iloci.evaluation.baselines on the
#: run's fold (the same learning and test sets).
BASELINES_METRIC = "baselines"


@dataclass(frozen=True)
class SweepSpec:
    """A parsed sweep spec (see the module docstring for the file)."""

    base: dict[str, Any]
    values: dict[str, Any]
    seeds: tuple[int, ...] = (0,)
    folds: tuple[int, ...] | None = None
    search: str = "grid"
    samples: int = 0
    random_seed: int = 0
    source: str = "<spec>"


@dataclass(frozen=True)
class Run:
    """One fold of one seed of one setting."""

    setting: dict[str, Any]
    seed: int
    fold: int
    config: dict[str, Any] = field(repr=False)
    key: str = ""


_SPEC_KEYS = {"base", "seeds", "folds", "search", "samples", "random_seed", "config", "values"}

#: Most settings one spec may name (the grid's product, or random ``samples``): each is
#: checked against the configuration schema before anything runs (~10-60 ms each), and
#: each is ``seeds x folds`` runs; 2,000 settings of 5 folds are already 10,000 runs.
MAX_SETTINGS = 2_000


def _error(source: str, message: str) -> ConfigError:
    return ConfigError(f"{source}: {message}")


def load_spec(path: str | Path) -> SweepSpec:
    """Read and check a sweep spec.

    Raises
    ------
    ConfigError
        The file is missing, not TOML, or has unknown keys or bad values
        (the message names the key and what is expected).
    """
    from iloci.config import load_config, read_config_file, read_toml

    path = Path(path)
    source = str(path)
    raw = read_toml(path, "sweep spec")
    unknown = set(raw) - _SPEC_KEYS
    if unknown:
        raise _error(source, f"unknown key(s) {sorted(unknown)}; a sweep spec has "
                     f"{sorted(_SPEC_KEYS)}.")
    base: dict[str, Any] = {}
    if "base" in raw:
        # what the base file says (checked by loading it), not its resolved
        # values: a component changed by [config] or [values] then takes its
        # own defaults for what the base leaves out
        # read once, through the reader every config file goes through
        base = read_config_file((path.parent / str(raw["base"])).resolve())
        load_config(base)
    fixed = dict(raw.get("config", {}))
    for sec, value in fixed.items():
        if not isinstance(value, dict):
            raise _error(source, f"[config] {sec} must be a table of values.")
        _update(base, sec, value)
    values = raw.get("values")
    if not isinstance(values, dict) or not values:
        raise _error(source, "[values] must name at least one swept key, e.g. "
                     '"learner.k_cutoff" = [0.25, 0.5, 1.0].')
    both = [key for key in values if key.count(".") == 1
            and key.split(".")[1] in fixed.get(key.split(".")[0], {})]
    if both:  # the swept values would silently replace the fixed one
        raise _error(source, f"{', '.join(both)} is both fixed in [config] and swept in "
                     "[values]; keep it in one of them.")
    for key, v in values.items():
        if isinstance(v, list):
            twice = sorted({json.dumps(x) for x in v if v.count(x) > 1})
            if twice:  # the same runs twice, counted as two in the report
                raise _error(source, f"{key} lists {', '.join(twice)} more than once; give "
                             "each value once.")
    search = raw.get("search", "grid")
    if search not in ("grid", "random"):
        raise _error(source, f"search must be 'grid' or 'random', got {search!r}.")
    for key, v in values.items():
        if key.count(".") != 1:
            raise _error(source, f"swept key {key!r} must be 'section.key', e.g. "
                         "'learner.k_cutoff'.")
        if isinstance(v, list):
            if not v:
                raise _error(source, f"{key}: an empty list of values.")
        elif isinstance(v, dict) and search == "random":
            if set(v) - {"low", "high", "log", "integer"} or not {"low", "high"} <= set(v):
                raise _error(source, f"{key}: a range is {{ low = .., high = .., log = "
                             "false, integer = false }.")
            if not v["low"] < v["high"] or (v.get("log") and v["low"] <= 0):
                raise _error(source, f"{key}: need low < high (and low > 0 with log).")
        else:
            raise _error(source, f"{key}: give a list of values"
                         + (" or a range { low, high }" if search == "random" else
                            " (ranges need search = 'random')") + ".")
    seeds = raw.get("seeds", [0])
    if not (isinstance(seeds, list) and seeds and all(isinstance(s, int) for s in seeds)):
        raise _error(source, "seeds must be a non-empty list of integers.")
    folds = raw.get("folds")
    if folds is not None and not (isinstance(folds, list) and folds
                                  and all(isinstance(k, int) and k >= 0 for k in folds)):
        raise _error(source, "folds must be a non-empty list of fold indices (0-based).")
    samples = raw.get("samples", 0)
    if search == "random" and not (isinstance(samples, int) and samples >= 1):
        raise _error(source, "search = 'random' needs samples = N (settings to draw, >= 1).")
    count = math.prod(len(v) if isinstance(v, list) else 1 for v in values.values()) \
        if search == "grid" else samples
    if count > MAX_SETTINGS:
        sizes = " x ".join(str(len(v)) for v in values.values() if isinstance(v, list))
        raise _error(source, f"{count:,} settings ({sizes if search == 'grid' else 'samples'}"
                     f") x {len(seeds)} seed(s); a sweep spec names at most {MAX_SETTINGS:,} "
                     "settings (iloci_ray.sweep.MAX_SETTINGS): sweep fewer values, split the "
                     "spec into several, or draw some with search = 'random' and samples = N.")
    spec = SweepSpec(base=base, values=dict(values), seeds=tuple(seeds),
                     folds=None if folds is None else tuple(folds), search=search,
                     samples=int(samples), random_seed=int(raw.get("random_seed", 0)),
                     source=source)
    # every swept value must make a valid config, and name data that exist: checked now,
    # before Ray starts, not run by run
    for setting in settings(spec):
        data = _resolve(spec, setting, spec.seeds[0]).get("data", {}).get("path")
        if data and not Path(data).exists():
            raise _error(source, f"setting {dict(setting)}: [data] path {data!r} does not "
                         f"exist (paths are read from the folder the sweep is started in, "
                         f"{Path.cwd()}).")
    return spec


def settings(spec: SweepSpec) -> list[dict[str, Any]]:
    """The settings of a sweep: the grid's product, or ``samples`` seeded draws."""
    keys = list(spec.values)
    if spec.search == "grid":
        return [dict(zip(keys, combo))
                for combo in itertools.product(*(spec.values[k] for k in keys))]
    rng = np.random.default_rng(spec.random_seed)
    out = []
    for _ in range(spec.samples):
        s: dict[str, Any] = {}
        for k in keys:
            v = spec.values[k]
            if isinstance(v, list):
                s[k] = v[int(rng.integers(len(v)))]
                continue
            lo, hi = float(v["low"]), float(v["high"])
            x = (float(np.exp(rng.uniform(np.log(lo), np.log(hi)))) if v.get("log")
                 else float(rng.uniform(lo, hi)))
            s[k] = int(round(x)) if v.get("integer") else x
        out.append(s)
    return out


def _resolve(spec: SweepSpec, setting: Mapping[str, Any], seed: int) -> dict[str, Any]:
    """The resolved config (every default filled in) of one setting and seed."""
    from iloci.config import load_config

    data = json.loads(json.dumps(spec.base))
    for dotted, value in setting.items():
        sec, key = dotted.split(".")
        _update(data, sec, {key: value})
    data.setdefault("evaluation", {})["seed"] = seed
    try:
        return load_config(data).to_dict()
    except ConfigError as exc:
        said = str(exc).removeprefix("<dict>: ")  # the spec is the source, not a mapping
        raise _error(spec.source, f"setting {dict(setting)}: {said}") from None


def _update(data: dict[str, Any], sec: str, values: Mapping[str, Any]) -> None:
    """Change section ``sec`` of a config mapping.

    Naming another component than the section names starts the section
    afresh, as :meth:`iloci.config.Config.replace` does: the parameters
    belong to the component they were written for.
    """
    old = data.get(sec)
    if ("name" in values and isinstance(old, dict) and "name" in old
            and old["name"] != values["name"]):
        data[sec] = dict(values)
    else:
        data.setdefault(sec, {}).update(values)


def run_key(config: Mapping[str, Any], fold: int, seed: int) -> str:
    """SHA-256 (hex, first 20 characters) of a resolved config, a fold and a seed."""
    blob = json.dumps({"config": config, "fold": fold, "seed": seed}, sort_keys=True,
                      separators=(",", ":"))
    return hashlib.sha256(blob.encode()).hexdigest()[:20]


def plan_runs(spec: SweepSpec) -> list[Run]:
    """Every run of the sweep, settings x seeds x folds, in that order.

    Raises
    ------
    ConfigError
        A fold in ``folds`` that the config's ``evaluation.folds`` does not have.
    """
    runs = []
    for setting in settings(spec):
        for seed in spec.seeds:
            config = _resolve(spec, setting, seed)
            n_folds = int(config["evaluation"]["folds"])
            folds = spec.folds if spec.folds is not None else tuple(range(n_folds))
            bad = [k for k in folds if k >= n_folds]
            if bad:
                raise _error(spec.source, f"fold(s) {bad} do not exist: the config has "
                             f"{n_folds} folds (0..{n_folds - 1}).")
            for k in folds:
                runs.append(Run(dict(setting), seed, k, config, run_key(config, k, seed)))
    return runs


def fold_run(config: dict[str, Any], fold: int) -> dict[str, Any]:
    """One run, in a Ray task: fold ``fold`` of the config's k-fold split; its metrics.

    The data are LASA or the config's ``[data] path`` (split as
    ``[evaluation] split`` says); the baselines run on the same fold when
    ``dtaidistance`` is installed (``baselines``: name -> CCR).
    """
    from iloci.data import load_lasa
    from iloci.evaluation.evaluate import fold_plan, run_fold

    from iloci.config import load_config
    from iloci.errors import MissingBackendError

    cfg = load_config(config)
    samples = None
    if cfg.data.path:
        from iloci.data.datasets import load_dataset
        dataset = load_dataset(cfg.data.path)
        demos, samples = dataset.demos, dataset.samples
    else:
        demos = load_lasa(list(cfg.data.shapes) or None)
    learn, test = fold_plan(demos, cfg, samples)[fold]
    res = run_fold(cfg, fold, [demos[i] for i in learn], [demos[i] for i in test],
                   baseline=False, details=False)
    fb = res.feedbacks
    out: dict[str, Any] = {
        "ccr": res.ccr, "feedbacks": len(fb),
        "rewarded": sum(1 for f in fb if f == 1) / max(1, len(fb)),
        "interactions_per_demo": res.interactions_per_demo, "entries": res.entries,
        "concepts": res.concepts, "generation_error": res.generation_error,
        "wall_seconds": res.wall_seconds}
    try:
        from iloci.evaluation.baselines import run_baselines
        runs = run_baselines([demos[i] for i in learn], [demos[i] for i in test])
        out[BASELINES_METRIC] = {name: r["ccr"] for name, r in runs.items()}
    except MissingBackendError:  # without the report extra: iloci's metrics only
        pass
    return out


def _store(out: Path, run: Run, metrics: dict[str, Any]) -> None:
    from iloci.data.files import write_atomic

    record = {"key": run.key, "setting": run.setting, "seed": run.seed, "fold": run.fold,
              "metrics": metrics, "config": run.config}
    data = json.dumps(record, indent=1, sort_keys=True).encode()
    write_atomic(out / "runs" / f"{run.key}.json", lambda fh: fh.write(data), mkdir=True)


def load_done(out: Path) -> dict[str, dict[str, Any]]:
    """Stored runs of ``out`` by key (a file that does not parse is ignored: rerun)."""
    done = {}
    for p in sorted((out / "runs").glob("*.json")):
        try:
            rec = json.loads(p.read_text())
            if rec["key"] == p.stem and set(RUN_METRICS) <= set(rec["metrics"]):
                done[p.stem] = rec
        except (OSError, ValueError, KeyError, TypeError):
            continue
    return done


#: Times a run whose worker died (or that failed otherwise than with an iloci error) is
#: started again before it is recorded as failed (``iloci sweep --retries``).
RETRIES = 2

#: What a worker that died without a word most likely met.
DIED = ("its Ray worker process died (killed by the out-of-memory killer or a signal, or "
        "crashed)")


def run_sweep(spec: SweepSpec, out: str | Path, *, address: str | None = None,
              jobs: int | None = None, retries: int = RETRIES,
              on_event: Callable[[str, Run, dict[str, Any] | None], None] | None = None,
              ) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Run every run of ``spec`` not stored in ``out`` yet, on Ray; store each at once.

    A run that fails is started again up to ``retries`` times when its worker
    died (out-of-memory killer, a signal, a crash) or it failed otherwise
    than with an iloci error; then, or at once for an iloci error (the same on
    every try: a bad setting, a back end missing on the cluster), it is
    recorded as failed and the other runs go on. A Ray started here is
    stopped, all of it, however the sweep ends (:mod:`iloci_ray.lifecycle`).

    Parameters
    ----------
    spec : SweepSpec
    out : path
        Output directory; ``out/runs/`` holds one JSON file per finished run.
    address : str, optional
        A running Ray cluster (``HOST:PORT``); None starts Ray here.
    jobs : int, optional
        Runs in flight at once (default: the cluster's CPUs).
    retries : int
        Times a failed run is started again (default :data:`RETRIES`).
    on_event : callable, optional
        ``on_event(kind, run, metrics)`` with kind ``"skipped"`` (stored
        before), ``"started"``, ``"finished"``, ``"retried"`` or ``"failed"``
        (``metrics`` then ``{"error": message, "attempts": n}``), or ``"restarted"``
        once when the Ray started here lost its raylet and is started again (``run``
        the first of the runs redone, ``metrics`` ``{"error", "runs", "restart",
        "of"}``): up to :data:`RAY_RESTARTS` times, the runs in flight redone
        without counting that try; after that the runs left are recorded failed.

    Returns
    -------
    records : list of dict
        Every finished run of the sweep (stored before and new), in plan order.
    info : dict
        ``runs``, ``reused`` (runs not recomputed), ``computed``,
        ``retried`` (runs that finished after a retry), ``failed`` (one dict
        per failed run: ``key``, ``setting``, ``seed``, ``fold``, ``error``,
        ``attempts``), ``retries``, ``ray_restarts``, ``wall_seconds``, ``jobs``,
        ``address``.
    """
    from iloci_ray.lifecycle import reap_orphans

    if retries < 0:
        raise InvalidInputError(f"retries must be >= 0, got {retries}.")
    out = Path(out)
    t0 = time.perf_counter()
    if address is None:  # a Ray left by a sweep killed with SIGKILL, even if nothing runs now
        reap_orphans()
    runs = plan_runs(spec)
    done = load_done(out)
    emit = on_event or (lambda kind, run, metrics: None)
    todo = []
    for run in runs:
        if run.key in done:
            emit("skipped", run, done[run.key]["metrics"])
        else:
            todo.append(run)
    # a setting repeated (e.g. random draws) is one run: compute it once
    unique = list({r.key: r for r in todo}.values())
    reused = len(runs) - len(todo)
    n_jobs = jobs
    attempts: dict[str, int] = {}
    failed: dict[str, dict[str, Any]] = {}
    waiting = list(unique)
    restarts = 0
    while waiting:
        lost = _run_on_ray(address, jobs, waiting, attempts, failed, done, out, retries,
                           emit)
        n_jobs = lost.pop("jobs", n_jobs)
        if not lost.get("lost"):
            break
        # the Ray started here lost its raylet (killed, out of memory): not the runs'
        # fault; it is stopped (all of it) and started afresh, the runs in flight redone
        restarts += 1
        if restarts > RAY_RESTARTS:
            why = (f"the Ray started for this sweep lost its raylet {restarts} times "
                   f"({lost['why']}); gave up")
            for run in waiting:
                failed[run.key] = {"key": run.key, "setting": run.setting, "seed": run.seed,
                                   "fold": run.fold, "error": why,
                                   "attempts": attempts.get(run.key, 0)}
                emit("failed", run, {"error": why, "attempts": attempts.get(run.key, 0)})
            break
        emit("restarted", waiting[0], {"error": lost["why"], "runs": len(waiting),
                                       "restart": restarts, "of": RAY_RESTARTS})
    records = [{"key": r.key, "setting": r.setting, "seed": r.seed, "fold": r.fold,
                **done[r.key]["metrics"]} for r in runs if r.key in done]
    info = {"runs": len(runs), "reused": reused, "computed": len(unique) - len(failed),
            "retried": sum(1 for k, n in attempts.items() if n > 1 and k not in failed),
            "ray_restarts": restarts,
            "failed": list(failed.values()), "retries": retries,
            "wall_seconds": time.perf_counter() - t0, "jobs": n_jobs, "address": address}
    return records, info


#: Times a Ray started by a sweep is started again after it lost its raylet.
RAY_RESTARTS = 2
#: Errors that say the local Ray itself is gone, not that a run failed.
_RAY_LOST = ("LocalRayletDiedError", "RaySystemError", "NodeDiedError")


def _ray_lost(err: BaseException, address: str | None) -> bool:
    """Whether ``err`` says the Ray this sweep started (no ``address``) is gone."""
    return address is None and type(err).__name__ in _RAY_LOST


def _run_on_ray(address: str | None, jobs: int | None, waiting: list[Run],
                attempts: dict[str, int], failed: dict[str, dict[str, Any]],
                done: dict[str, dict[str, Any]], out: Path, retries: int,
                emit: Callable[[str, Run, dict[str, Any] | None], None]) -> dict[str, Any]:
    """Run ``waiting`` (taken from the front) on one Ray session until none is left, or the
    Ray started here is lost: then the runs in flight go back to the front of ``waiting``
    (their try not counted) and ``{"lost": True, "why": ...}`` is returned."""
    from iloci.errors import IlociError
    from iloci_ray.executor import unwrap
    from iloci_ray.lifecycle import owned_ray

    with owned_ray(address, jobs) as (ray, refresh):
        n_jobs = jobs or max(1, int(ray.cluster_resources().get("CPU", 1)))
        remote = ray.remote(num_cpus=1, max_retries=0)(fold_run)
        running: dict[Any, Run] = {}
        lost: dict[str, Any] = {"jobs": n_jobs}

        def give_back(why: str) -> dict[str, Any]:
            back = list(running.values())
            for run in back:
                attempts[run.key] -= 1
            waiting[:0] = back
            running.clear()
            return {**lost, "lost": True, "why": why}

        try:
            while waiting or running:
                while waiting and len(running) < n_jobs:
                    run = waiting[0]
                    try:
                        ref = remote.remote(run.config, run.fold)
                    except Exception as exc:  # noqa: BLE001  (Ray itself failed)
                        if _ray_lost(unwrap(exc), address):
                            return give_back(_why(unwrap(exc)))
                        raise
                    waiting.pop(0)
                    attempts[run.key] = attempts.get(run.key, 0) + 1
                    running[ref] = run
                    emit("started", run, None)
                refresh()
                try:
                    ready, _ = ray.wait(list(running), num_returns=1)
                except Exception as exc:  # noqa: BLE001  (Ray itself failed)
                    if _ray_lost(unwrap(exc), address):
                        return give_back(_why(unwrap(exc)))
                    raise
                for ref in ready:
                    run = running[ref]
                    try:
                        metrics = ray.get(ref)
                    except Exception as exc:  # noqa: BLE001  (kept, reported, retried)
                        err = unwrap(exc)
                        if _ray_lost(err, address):
                            return give_back(_why(err))
                        running.pop(ref)
                        why = _why(err)
                        if isinstance(err, IlociError) or attempts[run.key] > retries:
                            failed[run.key] = {
                                "key": run.key, "setting": run.setting, "seed": run.seed,
                                "fold": run.fold, "error": why,
                                "attempts": attempts[run.key]}
                            emit("failed", run, {"error": why,
                                                 "attempts": attempts[run.key]})
                        else:
                            waiting.insert(0, run)
                            emit("retried", run, {"error": why,
                                                  "attempts": attempts[run.key]})
                        continue
                    running.pop(ref)
                    _store(out, run, metrics)
                    done[run.key] = {"metrics": metrics}
                    emit("finished", run, metrics)
        finally:
            for ref in running:
                with contextlib.suppress(Exception):  # a lost Ray cannot cancel
                    ray.cancel(ref, force=True)
    return lost


def _why(err: BaseException) -> str:
    """One line saying why a run failed."""
    from iloci.errors import IlociError

    if isinstance(err, IlociError):
        return f"{type(err).__name__}: {err}"
    name = type(err).__name__
    if name == "LocalRayletDiedError":
        return f"{name}: the Ray node's raylet process died (killed, or out of memory)"
    if name in ("WorkerCrashedError", "NodeDiedError", "OutOfMemoryError", "ActorDiedError"):
        return f"{name}: {DIED}"
    first = str(err).strip().splitlines()[0] if str(err).strip() else ""
    return f"{name}: {first[:300]}"


def summary_lines(info: dict[str, Any], records: list[dict[str, Any]], command: str
                  ) -> list[str]:
    """The table a sweep ends with: what ran, what failed, and how to resume."""
    failed = info["failed"]
    lines = [f"{info['runs']} runs: {len(records)} stored ({info['computed']} computed now, "
             f"{info['retried']} of them after a retry; {info['reused']} stored before), "
             f"{len(failed)} failed."]
    if info.get("ray_restarts"):
        lines.append(f"The Ray started for the sweep lost its raylet and was started again "
                     f"{info['ray_restarts']} time(s); the runs in flight then were redone.")
    if failed:
        lines.append(f"{'run':20s}  {'seed':>4s}  {'fold':>4s}  {'tries':>5s}  setting: error")
        for f in failed:
            lines.append(f"{f['key']:20s}  {f['seed']:4d}  {f['fold']:4d}  {f['attempts']:5d}  "
                         f"{f['setting']}: {f['error']}")
        lines.append(f"Every finished run is stored. Run the same command again to resume "
                     f"({command}): the {len(records)} stored run(s) are skipped and only "
                     f"the {len(failed)} failed one(s) run again; one that fails the same "
                     "way every time needs its error fixed first.")
    return lines


def other_spec(out: Path, source: str) -> str | None:
    """The spec of the report ``out`` holds when it is not ``source`` (another sweep's),
    else None (no report, or this spec's)."""
    try:
        said = json.loads((out / "summary.json").read_text(encoding="utf-8")).get("spec")
    except (OSError, ValueError, AttributeError):
        return None
    if not isinstance(said, str) or os.path.realpath(said) == os.path.realpath(source):
        return None
    return said


def check_out(out: str | Path) -> Path:
    """``out`` as a directory to write to (created), or an InvalidInputError."""
    from iloci.data.files import writable_dir
    return writable_dir(out, "--out")
