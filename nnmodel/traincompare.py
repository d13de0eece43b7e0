"""Train several neural models on one dataset and compare them honestly (``eap train-compare``).

Every model is trained with its recipe (``configs/train/NAME.yaml``), saved as a bundle,
then scored in **free-run simulation** under the start-up rule of :mod:`nnmodel.startup`
(every row starts at the same sample from the measured outputs of the start-up window, its
offset set over that window, and is scored after it) and in one-step-ahead prediction on the
test records, grouped as

- ``train_rh``: test records at the training RH levels,
- ``heldout_rh``: RH levels never seen in training (the generalisation the issue asks for),
- ``varying_rh``: records whose RH drifts during the record,
- ``measurement_like``: records simulated with physics the generator's model lacked.

The physics simulator that generated the data is scored on the same records: it is the
reference the networks learned from (its error is the sensor noise, except on the
measurement-like records).  The best linear model of the same training data
(:func:`nnmodel.linear.fit_linear`: ARX orders chosen on the validation data, refined for
the output error where that helps) is the row ``linear``, the yardstick every network is
measured against (``vs_linear_pct``: how far its test error lies below or above it); it
is saved as a bundle too (``models/linear``), which ``eap predict`` runs.
Scores are pooled over records: NRMSE = sqrt(Σe²/Σ(y−ȳ)²)
(ȳ per record), fit % = 100 (1 − NRMSE) as MATLAB ``compare``; RMSE in the output's unit.
Records are grouped into RH levels by :func:`physics.compare.cluster_rh` (the hygrometer's
tolerance, ``rh_tolerance`` %), as every other command does.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from physics.io.outputs import final_path, output_folder, preflight
from physics.compare import PhysicsPredictor, cluster_rh, model_rh
from physics.effects import CORE
from physics.errors import InputError
from physics.io.fileio import jsonable, write_json
from physics.solvers.frequency import frequency_response
from physics.pages.columns import number, reading_unit
from physics.pages.plotting import legend_outside, plain_log_axis, plt, rh_axis, save
from physics.pages.report import Report, colour, write_csv
from physics import signals

from physics.effects import ensure_registered, user_effect_files
from physics.execution.parallel import ParallelSettings, map_tasks, warm_up

from .bundle import load as load_bundle, save as save_bundle
from .dataset import Dataset, load_dataset
from .linear import LinearModel, fit_linear
from .models import MODELS
from .explain import group_facts, notes
from .recipes import load_recipe, make_model
from .shortfalls import data_facts, explain, sentences
from .startup import START_SAMPLES, free_run
from .tuning import tune as run_tuning

GROUPS = ("train_rh", "heldout_rh", "varying_rh", "measurement_like")
#: name of the linear yardstick's row
LINEAR = "linear"
#: the hygrometer's tolerance [%] within which records form one RH level (``--rh-tolerance``)
RH_TOLERANCE = 1.0


def group_of(entry: dict) -> str:
    if entry["extra_effects"]:
        return "measurement_like"
    if isinstance(entry["rh_pct"], dict):
        return "varying_rh"
    return "heldout_rh" if entry["heldout_rh"] else "train_rh"


def rh_levels(entries: list[dict], tolerance: float = RH_TOLERANCE) -> dict[str, float]:
    """The nominal RH level of every record at one RH (path -> level, %), grouped within the
    hygrometer's ``tolerance`` (:func:`physics.compare.cluster_rh`, as ``eap diagnose``)."""
    fixed = [e for e in entries if isinstance(e.get("rh_pct"), (int, float))]
    return dict(zip((e["path"] for e in fixed), cluster_rh([float(e["rh_pct"]) for e in fixed], tolerance))) \
        if fixed else {}


def _pooled(ys, yhats) -> dict:
    e2 = sum(float(np.sum((y - yh) ** 2)) for y, yh in zip(ys, yhats))
    v2 = sum(float(np.sum((y - np.mean(y)) ** 2)) for y in ys)
    n = sum(y.size for y in ys)
    nr = float(np.sqrt(e2 / v2)) if v2 > 0 else float("nan")
    corr = float(np.mean([np.corrcoef(y, yh)[0, 1] for y, yh in zip(ys, yhats)]))
    bias = sum(float(np.sum(y - yh)) for y, yh in zip(ys, yhats)) / n
    return {"rmse_m": float(np.sqrt(e2 / n)), "nrmse": nr, "fit_pct": 100.0 * (1.0 - nr), "correlation": corr,
            "mean_error": bias, "records": len(ys)}


def runner(simulate, n_init: int):
    """``run(record) -> (y_hat, start-up window)`` of a model under the start-up rule
    (:func:`nnmodel.startup.free_run`); ``simulate(record, y_init)`` runs it over a record."""
    def run(rec):
        return free_run(lambda y_init: simulate(rec, y_init), rec.y, n_init, f"record {rec.name!r}")
    return run


def network_runner(model):
    """:func:`runner` of a trained network (or any model with ``simulate`` and ``n_init_``)."""
    return runner(lambda rec, y0: model.simulate(rec.u, rec.rh if model.uses_rh else None, y_init=y0),
                  int(model.n_init_))


def _score(run, ds: Dataset, entries: list[dict], rh_tolerance: float = RH_TOLERANCE) -> dict:
    """Pooled metrics per group and per RH level for ``run(record) -> (y_hat, start-up
    window)`` (:func:`runner`), scored after the window."""
    by_group: dict[str, tuple[list, list]] = {g: ([], []) for g in GROUPS}
    by_rh: dict[float, tuple[list, list]] = {}
    levels = rh_levels([e for e in entries if group_of(e) in ("train_rh", "heldout_rh")], rh_tolerance)
    for e in entries:
        rec = ds.record(e)
        yh, w = run(rec)
        y, yh = rec.y[w:], yh[w:]
        g = group_of(e)
        by_group[g][0].append(y)
        by_group[g][1].append(yh)
        if e["path"] in levels:
            by_rh.setdefault(levels[e["path"]], ([], []))
            by_rh[levels[e["path"]]][0].append(y)
            by_rh[levels[e["path"]]][1].append(yh)
    out = {g: _pooled(*v) for g, v in by_group.items() if v[0]}
    core = [g for g in ("train_rh", "heldout_rh", "varying_rh") if g in out]
    ys = [y for g in core for y in by_group[g][0]]
    yhs = [y for g in core for y in by_group[g][1]]
    out["test"] = _pooled(ys, yhs)
    out["by_rh"] = {f"{rh:g}": _pooled(*v)["nrmse"] for rh, v in sorted(by_rh.items())}
    return out


def _small_signal_frf(simulate, fs: float, rh: float, rms: float = 0.3, f_max: float = 40.0):
    """FRF of any simulator from a periodic multisine (3 periods, the last 2 analysed)."""
    period = 40.0
    sig = signals.multisine(rms=rms, f_start=1.0 / period, f_stop=f_max, period=period, periods=3, fs=fs, seed=7)
    y = simulate(sig.v, np.full(sig.v.size, rh))
    n = int(round(period * fs))
    seg = slice(sig.v.size - 2 * n, sig.v.size)
    U, Y = np.fft.rfft(sig.v[seg]), np.fft.rfft(y[seg])
    k = 2 * np.arange(1, int(f_max * period) + 1)
    return k / (2 * period), Y[k] / U[k]


def train_compare(dataset: str | Path, models=None, out: str | Path = "runs/train-compare",
                  *, overrides: dict[str, dict] | None = None, max_time_s: float | None = None,
                  progress: bool = True, overwrite: bool = False, physics: str | None = None,
                  settings: ParallelSettings | None = None, tune: int | None = None,
                  rh_tolerance: float = RH_TOLERANCE, accelerator: str = "auto") -> dict:
    """Train ``models`` (kinds; default :func:`nnmodel.models.default_kinds`) on ``dataset``, save bundles under ``out/models``, and write
    ``compare.json``, ``metrics.csv``, plots and the page ``index.html`` in ``out`` (a folder written
    atomically under the policy of :mod:`physics.io.outputs`).  ``physics``: a device (name or
    YAML) whose simulator is scored beside the networks — by default the dataset's generator,
    none for measured data.  ``settings``: where the models train (:mod:`physics.execution.parallel`:
    one task per model, each reading the dataset from its path; default here).  ``tune``:
    trials per model of the search on validation data (:mod:`nnmodel.tuning`), the best
    trial's settings are trained and saved.  ``rh_tolerance`` [%]: records whose RH differ by
    less form one RH level.  ``accelerator``: ``auto`` (a GPU when torch sees one), ``cpu``
    or ``gpu`` (:func:`nnmodel.training.resolve_accelerator`; a ``--set MODEL.accelerator``
    wins)."""
    from .training import resolve_accelerator
    if models is None:
        from .models import default_kinds
        models = default_kinds()
    if not (isinstance(rh_tolerance, (int, float)) and rh_tolerance >= 0):
        raise InputError(f"--rh-tolerance {rh_tolerance!r}: must be a non-negative number of % RH")
    device = resolve_accelerator(accelerator)
    preflight(out, inputs=[dataset], overwrite=overwrite)
    warm_up(settings)   # the workers start while the dataset is read and the physics scored
    ds = load_dataset(dataset)
    with output_folder(out, inputs=[dataset], overwrite=overwrite) as tmp:
        return _train_compare(ds, dataset, models, tmp, overrides, max_time_s, progress, physics, settings, tune,
                              float(rh_tolerance), device)


def _train_compare(ds, dataset, models, out: Path, overrides, max_time_s, progress, physics, settings,
                   tune=None, rh_tolerance: float = RH_TOLERANCE, accelerator: str = "cpu") -> dict:
    if not ds.entries("train"):
        raise InputError(f"{dataset}: no training records")
    test_entries = ds.entries("test")
    if not test_entries:
        raise InputError(f"{dataset}: no test records to compare the models on; add some with "
                         "`eap dataset --test FILE`")
    gen = ds.meta["generator"]
    device = physics or gen.get("device")
    effects = gen.get("effects") if physics is None else "default"
    results: dict[str, dict] = {}
    physics_rows = {}
    if device is not None:
        results["physics"], physics_rows["physics"] = _physics_row(ds, device, effects, physics is None, test_entries,
                                                                   rh_tolerance)
    local = settings is None or settings.serial
    val_fraction = _val_fraction(ds)
    tasks = [{"name": LINEAR, "dataset": str(ds.path), "val_fraction": val_fraction, "echo": progress and local,
              "bundle": str(out / "models" / LINEAR), "rh_tolerance": rh_tolerance}]
    for name in models:
        ov = dict((overrides or {}).get(name, {}))
        if val_fraction is not None:        # the dataset's own split when it has no validation records
            ov.setdefault("val_fraction", val_fraction)
        if not progress or not local:
            ov.setdefault("progress_bar", False)
        if max_time_s is not None:
            ov["max_time"] = float(max_time_s)
        ov.setdefault("accelerator", accelerator)
        if getattr(MODELS.get(name), "NEEDS_PHYSICS", False):
            if device is None and "device" not in ov:
                raise InputError(f"the {name} model needs a physics model: give --physics DEVICE "
                                 f"(or --set {name}.device=...)")
            ov.setdefault("device", device)   # its physics: the dataset's (or --physics) device
        make_model(name, ov)                  # a bad recipe or --set fails here, before any training
        tasks.append({"name": name, "overrides": ov, "dataset": str(ds.path), "bundle": str(out / "models" / name),
                      "echo": progress and local, "effect_files": user_effect_files(), "rh_tolerance": rh_tolerance})
    tuning = _tune(tasks[1:], tune, str(ds.path), settings, progress) if tune else {}
    if progress and not local:
        print(f"training {', '.join(models)} on {settings.workers if not settings.scheduler else 'the cluster'} "
              f"worker(s) ...", flush=True)
    runs = map_tasks(_train_one, tasks, settings, desc="models", progress=False, cost=_training_cost)
    trained, linear_rows = {}, {}
    for task, res in zip(tasks, runs):
        name = task["name"]
        results[name] = res
        if name == LINEAR:
            lin = LinearModel.from_card(res["linear"])
            linear_rows[name] = _linear_runner(lin)
        else:
            model = load_bundle(task["bundle"]).model
            if model.__dict__.get("reference_start_", {}).get("reference") == "physics":
                base = _physics_base_row(model, results.get("physics"), ds, test_entries, rh_tolerance)
                if base is not None:   # the physics the hybrid starts from, alone, when no row shows it yet
                    results["physics_base"], physics_rows["physics_base"] = base
            if name in tuning:
                res["tuning"] = tuning[name]
            trained[name] = model
        if progress and not local:
            _echo_result(name, res)
    for name in _fallbacks(results, trained, out, ds):
        trained[name] = trained[results[name]["falls_back_to"]]
    _compare_with_linear(results)
    facts = data_facts(ds, LinearModel.from_card(results[LINEAR]["linear"]))
    for name, model in trained.items():
        results[name]["shortfalls"] = explain(name, results[name], results, model, facts, LINEAR)
    summary = {"dataset": str(final_path(ds.path)), "dataset_hash": ds.hash, "fs_Hz": ds.fs,
               "generator": {"device": gen.get("device"), "effects": gen.get("effects"), "tool": gen.get("tool")},
               "physics": None if device is None else {"device": str(device), "is_generator": physics is None},
               "output": output_reading(ds), "accelerator": accelerator, "rh_tolerance_pct": rh_tolerance,
               "noise_floor_m": ds.meta.get("noise_floor_m"), "skip_samples": START_SAMPLES,
               "start_up": START_UP, "models": results,
               "best_heldout": _best(results), "test_groups": group_facts(test_entries, group_of)}
    _plots(ds, test_entries, physics_rows, linear_rows, trained, results, out, summary["output"])
    if tuning:
        _tuning_plot(tuning, out)
    write_json(out / "compare.json", summary)
    write_csv(table_rows(results), out / "metrics.csv")
    _report(summary, out)
    return summary


#: The start-up rule in one sentence (page and compare.json; :mod:`nnmodel.startup`).
START_UP = (f"every free run is scored from the same sample on: a model is handed the measured outputs of the "
            f"record's first max({START_SAMPLES}, n_init) samples, its start-up window (a network's state is set "
            "from the last n_init of them; its input channels run from the record's first sample as in training: "
            "memory filters, and its linear start from the first measured outputs, as the linear row does); the "
            "physics simulator starts from rest; each row is then shifted by its mean error over the window (zero "
            "for a model handed it, the sensor's zero for the physics)")


def _physics_row(ds, device, effects, is_generator: bool, entries, rh_tolerance=RH_TOLERANCE) -> tuple[dict, object]:
    """(result row, run) of the physics simulator of ``device`` on the test records."""
    if not ds.has_rh:
        raise InputError(f"--physics {device}: the dataset has no relative humidity, which the physics "
                         "model needs; build it with --rh")
    physics_model = PhysicsPredictor.from_device(device, effects)
    # measured RH is noisy: the physics gets the slow RH (compare.model_rh)
    run = runner(lambda rec, _: physics_model(rec.u, model_rh(rec.rh, rec.fs), rec.fs), 0)
    t0 = time.perf_counter()
    kind = "physics simulator (generator)" if is_generator else f"physics model {device} (--physics)"
    row = {"kind": kind, "effects": list(physics_model.model.effect_ids), "device": physics_model.model.device.name,
           "free_run": _score(run, ds, entries, rh_tolerance), "n_parameters": None, "train_time_s": 0.0,
           "inference_samples_per_s": _speed(run, ds, entries)}
    row["eval_time_s"] = time.perf_counter() - t0
    return row, run


def _tune(tasks: list[dict], n_trials: int, dataset: str, settings, progress: bool) -> dict:
    """Tune each model task (:mod:`nnmodel.tuning`) and set its overrides to the chosen trial's
    (the caller's ``--set`` values win); returns the tuning record of each model."""
    tuning = {}
    for task in tasks:
        name = task["name"]
        if progress:
            print(f"tuning {name}: {n_trials} trials on the validation data ...", flush=True)
        tuning[name] = run_tuning(name, load_recipe(name, task["overrides"]), task["overrides"], n_trials,
                                  dataset, settings, task["effect_files"], print if progress else None)
        task["overrides"] = {**tuning[name]["best"]["overrides"], **task["overrides"]}
        task["tuning"] = tuning[name]
    return tuning


def _val_fraction(ds: Dataset) -> float | None:
    """The dataset's validation fraction when it has no validation records (else None)."""
    if ds.entries("validation"):
        return None
    vf = ds.meta.get("val_fraction")
    return None if vf is None else float(vf)


def _linear_runner(lin: LinearModel):
    """:func:`runner` of the linear yardstick: handed the start-up window like a network, it
    runs from the record's first ``n_init`` samples as a network's linear start does (so a
    network whose correction was dropped scores exactly this row)."""
    def simulate(rec, y0):
        yh = lin.simulate(rec.u, rec.rh if lin.uses_rh else None, y_init=y0[:lin.n_init])
        yh[:y0.size] = y0
        return yh
    return runner(simulate, lin.n_init)


def _train_linear(task: dict) -> dict:
    """Fit, score and save the linear yardstick (a task like :func:`_train_one`): its bundle
    is the network that runs exactly this linear model (:func:`nnmodel.models.ff.as_network`)."""
    from .models.ff import as_network
    from .models.structure import validation_nrmse
    ds = load_dataset(task["dataset"])
    train, val = ds.records("train"), ds.records("validation") or None
    entries = ds.entries("test")
    if task["echo"]:
        print("fitting the linear yardstick ...", flush=True)
    t1 = time.perf_counter()
    vf = 0.2 if task["val_fraction"] is None else task["val_fraction"]
    lin = fit_linear(train, val, vf)
    fit_time = time.perf_counter() - t1
    free = _linear_runner(lin)

    def one_step(rec):
        w = max(START_SAMPLES, lin.n_init)
        return lin.one_step(rec.u, rec.rh if lin.uses_rh else None, rec.y), w

    net = as_network(lin, train, val_fraction=vf)
    res = {"kind": lin.label(), "n_parameters": lin.na + lin.nb + 1 + int(lin.uses_rh), "train_time_s": fit_time,
           "free_run": _score(free, ds, entries, task["rh_tolerance"]),
           "one_step": _score(one_step, ds, entries, task["rh_tolerance"]),
           "validation": {"nrmse": validation_nrmse(net, train, val)},
           "inference_samples_per_s": _speed(free, ds, entries), "linear": lin.card()}
    save_bundle(net, task["bundle"], dataset_hash=ds.hash, overwrite=True, output=(ds.output.name, ds.output.unit),
                metrics={"free_run": res["free_run"], "one_step": res["one_step"]},
                notes=f"the linear yardstick of eap train-compare on {final_path(ds.path)}: {lin.label()}, run as a "
                      "network whose map is that linear model (no hidden layer)",
                extra={"linear_yardstick": lin.card()})
    if task["echo"]:
        _echo_result(LINEAR, res)
    return res


def _compare_with_linear(results: dict) -> None:
    """Every row but the yardstick says how far its test error lies from the linear row's
    (``vs_linear_pct``: negative below, positive above)."""
    lin = results.get(LINEAR)
    if lin is None:
        return
    ref = lin["free_run"]["test"]["nrmse"]
    for name, row in results.items():
        if name != LINEAR and np.isfinite(ref) and ref > 0:
            row["vs_linear_pct"] = 100.0 * (row["free_run"]["test"]["nrmse"] / ref - 1.0)


def _train_one(task: dict) -> dict:
    """Train, score and save one model (a task of :func:`physics.execution.parallel.map_tasks`: in this
    process or on a worker, which reads the dataset from its path); returns its result row."""
    from .models.structure import selection_score
    from .training import device_name
    if task["name"] == LINEAR:
        return _train_linear(task)
    ensure_registered(task["effect_files"])
    ds = load_dataset(task["dataset"])
    train, val = ds.records("train"), ds.records("validation") or None
    entries = ds.entries("test")
    name = task["name"]
    model = make_model(name, task["overrides"])
    if task["echo"]:
        print(f"training {name} ...", flush=True)
    t1 = time.perf_counter()
    model.fit(train, val)
    fit_time = time.perf_counter() - t1
    free = network_runner(model)

    def one_step(rec):
        return model.predict(rec.u, rec.rh, y=rec.y, steps_ahead=1), max(START_SAMPLES, int(model.n_init_))

    cv = model.__dict__.get("cross_validation_")
    res = {"kind": name, "n_parameters": int(model.n_parameters), "train_time_s": fit_time,
           "free_run": _score(free, ds, entries, task["rh_tolerance"]),
           "one_step": _score(one_step, ds, entries, task["rh_tolerance"]),
           "validation": {"nrmse": selection_score(model, train, val), "cross_validation": cv and jsonable(cv)},
           "inference_samples_per_s": _speed(free, ds, entries),
           "rh_range_trained_pct": list(model.rh_range_) if model.rh_range_ else None,
           "training": {**_budget(model), "device": device_name(model.accelerator)},
           "history": list(getattr(model, "history_", None) or []),
           "reference_start": getattr(model, "reference_start_", None)}
    save_bundle(model, task["bundle"], dataset_hash=ds.hash, overwrite=True, output=(ds.output.name, ds.output.unit),
                metrics={"free_run": res["free_run"], "one_step": res["one_step"]},
                notes=f"trained by eap train-compare on {final_path(ds.path)}",
                extra={"tuning": task["tuning"]} if task.get("tuning") else None)
    if task["echo"]:
        _echo_result(name, res)
    return res


def _budget(model) -> dict:
    """The training budget a model used: epochs run and the epoch budget (None for a
    least-squares fit)."""
    s = getattr(model, "training_summary_", None) or {}
    return {"epochs": s.get("epochs_run"), "max_epochs": s.get("max_epochs")}


def _training_cost(task: dict) -> float:
    """Relative training cost, to start the dearest models first: models trained in closed
    loop (back-propagation through time over windows, ``horizon`` > 1) cost more than those
    trained one step ahead or by least squares; the linear yardstick costs seconds."""
    if task["name"] == LINEAR:
        return 0.1
    return 1.0 if int(make_model(task["name"], task["overrides"]).horizon) <= 1 else 4.0


def _echo_result(name: str, res: dict) -> None:
    fr = res["free_run"]
    held = f", held-out RH {100 * fr['heldout_rh']['nrmse']:.2f} %" if "heldout_rh" in fr else ""
    print(f"  {name}: {res['train_time_s']:.1f} s, free-run NRMSE test {100 * fr['test']['nrmse']:.2f} %{held}",
          flush=True)


def _physics_base_row(model, physics_row: dict | None, ds: Dataset, entries, rh_tolerance=RH_TOLERANCE):
    """Score of a residual model's own physics part (its device and effects, without the
    network) when no physics row shows that same model: (result row, run) or None."""
    pm = model._physics_model()
    if physics_row is not None and pm.device.name == physics_row.get("device") \
            and list(pm.effect_ids) == list(physics_row.get("effects") or []):
        return None
    pred = PhysicsPredictor(pm)
    run = runner(lambda rec, _: pred(rec.u, model_rh(rec.rh, rec.fs), rec.fs), 0)
    row = {"kind": "physics part of the hybrid (no network)", "effects": list(pm.effect_ids),
           "device": pm.device.name, "free_run": _score(run, ds, entries, rh_tolerance), "n_parameters": None,
           "train_time_s": 0.0, "inference_samples_per_s": _speed(run, ds, entries)}
    return row, run


def beats(parent, child, train, val) -> tuple[bool, str]:
    """Whether the fitted model ``parent`` validates better than ``child`` by more than the
    uncertainty the keep-over-linear rule allows (:mod:`nnmodel.models.crossval`): fold by fold
    by more than the spread when both were cross-validated, else by more than
    :data:`~nnmodel.models.base.GAIN_SE` standard errors of the paired squared-error gain by
    batch means over the validation data (:func:`nnmodel.batches.paired_gain`); and why."""
    from .batches import GAIN_BLOCKS, GAIN_SE, paired_gain
    from .models.crossval import paired_win
    from .models.structure import validation_errors
    cp, cc = parent.__dict__.get("cross_validation_"), child.__dict__.get("cross_validation_")
    if cp and cc:
        wins, gain, spread = paired_win(cc["score_folds"], cp["score_folds"])
        return wins, f"by {100 * gain:.3g} % NRMSE over the folds, against a spread of {100 * spread:.3g} %"
    ep, ec = validation_errors(parent, train, val), validation_errors(child, train, val)
    if ec is None:
        return ep is not None, "its own free run diverged on validation"
    if ep is None:
        return False, "the other's free run diverged on validation"
    gain, se, blocks = paired_gain(ec[0], ep[0], GAIN_BLOCKS)
    ok = gain > 0 and (not np.isfinite(se) or gain > GAIN_SE * se)
    return ok, f"a squared-error gain of {gain / se:.1f} standard errors over {blocks} blocks" if np.isfinite(se) \
        and se > 0 else f"a squared-error gain of {gain:.3g} (its uncertainty unknown)"


def _fallbacks(results: dict, trained: dict, out: Path, ds: Dataset) -> list[str]:
    """A grey box (a network whose reference is its physics) is never worse on validation than
    its better parent: its physics part (its own keep rule sees to that) or the best pure
    network of the run.  When that network validates better by more than the uncertainty
    (:func:`beats`), the grey box's row and bundle become that network's, and the row says so
    (``falls_back_to``); returns those rows."""
    out_rows = []
    pure = {k: m for k, m in trained.items()
            if (m.__dict__.get("reference_start_") or {}).get("reference") != "physics"}
    train, val = ds.records("train"), ds.records("validation") or None
    for name, model in trained.items():
        if name in pure:
            continue
        own = results[name]["validation"]["nrmse"]
        scores = {k: results[k]["validation"]["nrmse"] for k in pure}
        if not scores:
            continue
        parent = min(scores, key=scores.get)
        if not scores[parent] < own:
            continue
        wins, how = beats(pure[parent], model, train, val)
        if not wins:
            results[name]["parent_not_better"] = (f"{parent} validates lower ({100 * scores[parent]:.3g} % against "
                                                  f"{100 * own:.3g} %) but not beyond the uncertainty: {how}")
            continue
        row = results[name]
        results[name] = {**{k: v for k, v in results[parent].items() if k not in ("tuning", "shortfalls")},
                         "kind": f"{parent} (the {name} row fell back to it)", "falls_back_to": parent,
                         "fallback_evidence": how,
                         "own": {"kind": row["kind"], "free_run": row["free_run"], "validation": row["validation"],
                                 "n_parameters": row["n_parameters"], "reference": "physics"}}
        save_bundle(trained[parent], out / "models" / name, dataset_hash=ds.hash, overwrite=True,
                    output=(ds.output.name, ds.output.unit), metrics={"free_run": results[parent]["free_run"]},
                    notes=f"eap train-compare: {name} validated worse ({100 * own:.3g} % NRMSE) than its parent "
                          f"{parent} ({100 * scores[parent]:.3g} %; {how}), so it falls back to {parent}",
                    extra={"falls_back_from": name})
        out_rows.append(name)
    return out_rows


def _is_physics(name: str, row: dict) -> bool:
    return row.get("n_parameters") is None and str(row.get("kind", "")).startswith("physics")


def is_reference(name: str, row: dict) -> bool:
    """Rows that are not networks: the physics rows and the linear yardstick."""
    return name == LINEAR or _is_physics(name, row)


def _speed(run, ds: Dataset, entries) -> float:
    rec = ds.record(max(entries, key=lambda e: e["samples"]))
    t0 = time.perf_counter()
    run(rec)
    return rec.u.size / (time.perf_counter() - t0)


def _best(results: dict) -> dict:
    """The best network on held-out RH (or on the whole test set when nothing is held out)."""
    nets = {k: v for k, v in results.items() if not is_reference(k, v)}
    group = "heldout_rh" if any("heldout_rh" in v["free_run"] for v in nets.values()) else "test"
    nets = {k: v for k, v in nets.items() if group in v["free_run"]}
    if not nets:
        return {}
    k = min(nets, key=lambda n: nets[n]["free_run"][group]["nrmse"])
    return {"model": k, "nrmse": nets[k]["free_run"][group]["nrmse"],
            "group": "held-out RH" if group == "heldout_rh" else "test records"}


def table_rows(results: dict) -> list[dict]:
    """One row per model: free-run NRMSE by test group, the test RMSE in the output's unit
    (``_m``: SI), one-step NRMSE and ``vs_linear_pct`` (metrics.csv and the page)."""
    rows = []
    nan = float("nan")
    for name, r in results.items():
        fr = r["free_run"]
        rows.append({"model": name, "parameters": r["n_parameters"], "train_time_s": r["train_time_s"],
                     "samples_per_s": r["inference_samples_per_s"],
                     "rmse_test_m": fr["test"]["rmse_m"], "nrmse_test_pct": 100 * fr["test"]["nrmse"],
                     "nrmse_heldout_rh_pct": 100 * fr.get("heldout_rh", {}).get("nrmse", nan),
                     "nrmse_varying_rh_pct": 100 * fr.get("varying_rh", {}).get("nrmse", nan),
                     "nrmse_measurement_like_pct": 100 * fr.get("measurement_like", {}).get("nrmse", nan),
                     "fit_heldout_pct": fr.get("heldout_rh", {}).get("fit_pct", nan),
                     "corr_heldout": fr.get("heldout_rh", {}).get("correlation", nan),
                     "one_step_nrmse_test_pct": 100 * r["one_step"]["test"]["nrmse"] if "one_step" in r else None,
                     "vs_linear_pct": r.get("vs_linear_pct")})
    return rows


def vs_linear_text(pct: float | None) -> str:
    """A row's test error relative to the linear row, as the terminal and the page show it:
    ``−13.8 %`` below, ``+2.1 %`` above, ``–`` for the yardstick itself."""
    if pct is None or not np.isfinite(pct):
        return "–"
    return f"{pct:+.1f} %".replace("-", "−")


def page_rows(results: dict) -> list[dict]:
    """:func:`table_rows` as the page shows them: ``vs linear`` as :func:`vs_linear_text`."""
    return [{**{k: v for k, v in r.items() if k != "vs_linear_pct"}, "vs linear": vs_linear_text(r["vs_linear_pct"])}
            for r in table_rows(results)]


def format_table(summary: dict) -> str:
    rows = table_rows(summary["models"])
    output = summary.get("output") or {"name": "deflection", "unit": "m"}
    sizes = [r["rmse_test_m"] for r in rows if np.isfinite(r["rmse_test_m"]) and r["rmse_test_m"] > 0]
    unit, k = reading_unit(output["unit"], float(np.median(sizes)) if sizes else None)
    cols = [("test %", "nrmse_test_pct", 8), ("held-out %", "nrmse_heldout_rh_pct", 10),
            ("varying %", "nrmse_varying_rh_pct", 9), ("meas-like %", "nrmse_measurement_like_pct", 11)]
    cols = [c for c in cols if c[1] == "nrmse_test_pct" or any(np.isfinite(r[c[1]]) for r in rows)]
    rmse_head = f"RMSE {unit}"
    width = max(9, len(rmse_head))
    head = f"{'model':8s} {'params':>8s} {'train s':>8s} {'samples/s':>10s} {rmse_head:>{width}s} " + \
        " ".join(f"{h:>{w}s}" for h, _, w in cols) + f" {'1-step %':>8s} {'vs linear':>9s}"
    lines = [head, "-" * len(head)]
    for r in rows:
        p = "-" if r["parameters"] is None else str(r["parameters"])
        one = "-" if r["one_step_nrmse_test_pct"] is None else f"{r['one_step_nrmse_test_pct']:.2f}"
        lines.append(f"{r['model']:8s} {p:>8s} {r['train_time_s']:8.1f} {r['samples_per_s']:10.3g} "
                     f"{number(k * r['rmse_test_m']):>{width}s} "
                     + " ".join(f"{r[c]:{w}.2f}" for _, c, w in cols)
                     + f" {one:>8s} {vs_linear_text(r['vs_linear_pct']):>9s}")
    phys = summary.get("physics")
    note = "" if phys is None else ("; the physics row is the simulator that generated the data" if phys["is_generator"]
                                    else f"; the physics row is the device {phys['device']} named with --physics")
    lin = summary["models"].get(LINEAR)
    if lin is not None:
        note += f"; the linear row is {lin['kind']}, 'vs linear' the test NRMSE relative to it"
    lines.append(f"free-run test RMSE [{unit}] and NRMSE (RMSE/std of the measurement, pooled over records), scored "
                 "after each record's start-up window" + note)
    return "\n".join(lines)


def tuning_rows(tuned: dict) -> list[dict]:
    """One row per trial of every tuned model (the page's trial table)."""
    rows = []
    for name, t in tuned.items():
        for r in t["trials"]:
            v = r["validation_nrmse"]
            sp = r.get("spread")
            rows.append({"model": name, "trial": r["trial"], "best": "yes" if r["trial"] == t["best"]["trial"] else "",
                         "validation_nrmse_pct": None if v is None else 100 * v,
                         "cv_spread_pct": None if sp is None or not np.isfinite(sp) else 100 * sp,
                         "fit_s": r["fit_time_s"],
                         "settings": ", ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}"
                                               for k, v in r["params"].items()) + (f" (failed: {r['error']})"
                                                                                   if r["error"] else "")})
    return rows


def _tuning_plot(tuned: dict, out: Path) -> None:
    """Validation score of every trial, and the best so far, per tuned model."""
    fig, ax = plt.subplots(figsize=(7, 3.5))
    for name, t in tuned.items():
        x = [r["trial"] for r in t["trials"]]
        y = [np.nan if r["validation_nrmse"] is None else 100 * r["validation_nrmse"] for r in t["trials"]]
        ax.plot(x, y, "o", ms=4, color=colour(name), alpha=0.6, label=f"{name} trials")
        ax.plot(x, np.fmin.accumulate(np.where(np.isnan(y), np.inf, y)), "-", color=colour(name),
                label=f"{name} best so far")
    ax.set_xlabel("trial")
    ax.set_ylabel("free-run NRMSE on validation [%]")
    ax.set_yscale("log")
    plain_log_axis(ax)
    ax.grid(alpha=0.3, which="both")
    legend_outside(ax)
    save(fig, out / "tuning.png")


#: How each test group reads in a caption.
GROUP_LABELS = {"train_rh": "trained-RH", "heldout_rh": "held-out-RH", "varying_rh": "drifting-RH",
                "measurement_like": "measurement-like"}


def group_label(group: str, with_rh: bool) -> str:
    """A test group as a caption names it ("trained-RH test record"); records without a humidity
    channel are plain test records."""
    return f"{GROUP_LABELS[group]} test" if with_rh or group != "train_rh" else "test"


def output_reading(ds) -> dict:
    """The dataset's output ``{name, unit}`` with ``magnitude``, the largest absolute value
    of its training records, which picks the unit every table and plot of the page reads it
    in (:func:`physics.pages.columns.reading_unit`)."""
    output = dict(ds.meta.get("output") or {"name": "deflection", "unit": "m"})
    output["magnitude"] = float(max(np.max(np.abs(r.y)) for r in ds.records("train")))
    return output


def _plots(ds, entries, physics_rows, linear_rows, trained, results, out: Path, output: dict) -> None:
    qty = output["name"]
    unit, k = reading_unit(output["unit"], output.get("magnitude"))
    # time overlays: one record of each group
    for g in GROUPS:
        es = [e for e in entries if group_of(e) == g]
        if not es:
            continue
        rec = ds.record(es[0])
        t = np.arange(rec.u.size) / rec.fs
        fig, ax = plt.subplots(2, 1, figsize=(9, 5), sharex=True)
        ax[0].plot(t, k * rec.y, color=colour("measurement"), lw=1.0, label="measurement")
        for label, run in {**physics_rows, **linear_rows}.items():
            ax[0].plot(t, k * run(rec)[0], color=colour(label), lw=0.8, label=label)
        for name, m in trained.items():
            yh = network_runner(m)(rec)[0]
            ax[0].plot(t, k * yh, color=colour(name), lw=0.8, label=name)
            ax[1].plot(t, k * (rec.y - yh), color=colour(name), lw=0.6, label=name)
        ax[0].set_ylabel(f"{qty} [{unit}]")
        ax[1].set_ylabel(f"residual [{unit}]")
        ax[1].set_xlabel("time [s]")
        legend_outside(ax[0])
        ax[0].set_title(f"{group_label(g, ds.has_rh)} record {es[0]['path']}", fontsize=10)
        save(fig, out / f"overlay_{g}.png")
    _plot_losses(results, out / "losses.png")
    if not ds.has_rh or not physics_rows:
        return  # no RH levels to plot against, no closed form to compare with
    # error by RH
    fig, ax = plt.subplots(figsize=(7, 3.5))
    levels = []
    for name, r in results.items():
        rh = r["free_run"]["by_rh"]
        if rh:
            xs = [float(k) for k in rh]
            levels += xs
            ax.plot(xs, [100 * v for v in rh.values()], "o-", color=colour(name), label=name)
    held = ds.meta["rh_levels"]["held_out"]
    for h in held:
        ax.axvline(h, color="0.85", zorder=0)
    rh_axis(ax, levels + list(held))
    ax.set_xlabel("RH [%] (nominal level; grey: held out)")
    ax.set_ylabel("free-run NRMSE [%]")
    ax.set_yscale("log")
    plain_log_axis(ax)
    legend_outside(ax)
    ax.grid(alpha=0.3)
    save(fig, out / "error_by_rh.png")
    # small-signal Bode: networks vs the physics closed form
    gen = ds.meta["generator"]
    if gen.get("device") is None:
        return
    rh = float(np.median(ds.meta["rh_levels"]["train"]))
    fmax = min(40.0, 0.4 * ds.fs)
    resp = {}
    for name, m in trained.items():
        f, H = _small_signal_frf(lambda v, r, m=m: m.simulate(v, r), ds.fs, rh, f_max=fmax)
        resp[name] = H
    f_ref, _ = _small_signal_frf(lambda v, r: v, ds.fs, rh, f_max=fmax)
    resp_phys = frequency_response(gen["device"], gen["effects"], f_ref, rh=rh).deflection
    fig, ax = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    ax[0].loglog(f_ref, 1e3 * np.abs(resp_phys), "k", lw=1.5, label="physics (closed form)")
    ax[1].semilogx(f_ref, np.degrees(np.unwrap(np.angle(resp_phys))), "k", lw=1.5)
    for name, H in resp.items():
        ax[0].loglog(f_ref, 1e3 * np.abs(H), color=colour(name), lw=0.9, label=name)
        ax[1].semilogx(f_ref, np.degrees(np.unwrap(np.angle(H))), color=colour(name), lw=0.9)
    ax[0].set_ylabel("|H| [mm/V]")
    ax[1].set_ylabel("phase [°]")
    ax[1].set_xlabel("frequency [Hz]")
    legend_outside(ax[0])
    ax[0].set_title(f"small-signal response at RH {rh:.0f} % (multisine 0.3 V rms)", fontsize=10)
    for a in ax:
        a.grid(alpha=0.3, which="both")
    save(fig, out / "bode.png")


def _plot_losses(results: dict, path: Path) -> bool:
    """Training curves of the networks trained by gradient descent, on one scale: √train_loss
    (RMS of the normalised output on training windows) and val_loss (RMS free-run error of
    the normalised output on whole validation records)."""
    curves = {n: [h for h in r.get("history") or [] if h.get("epoch", -1) >= 0] for n, r in results.items()}
    curves = {n: h for n, h in curves.items() if any("train_loss" in x for x in h)}
    if not curves:
        return False
    fig, ax = plt.subplots(figsize=(7, 3.5))
    for n, h in curves.items():
        ep = [x["epoch"] + 1 for x in h if "train_loss" in x]
        ax.plot(ep, [np.sqrt(x["train_loss"]) for x in h if "train_loss" in x], color=colour(n), lw=1.0, ls=":",
                label=f"{n}: √train_loss")
        ev = [x["epoch"] + 1 for x in h if "val_loss" in x]
        if ev:
            ax.plot(ev, [x["val_loss"] for x in h if "val_loss" in x], color=colour(n), lw=1.3,
                    label=f"{n}: val_loss")
    ax.set_yscale("log")
    plain_log_axis(ax)
    ax.set_xlabel("epoch")
    ax.set_ylabel("RMS error of the normalised output")
    legend_outside(ax)
    ax.grid(alpha=0.3, which="both")
    save(fig, path)
    return True


def diagnose_command(summary: dict) -> str | None:
    """The command that diagnoses the measurement-like records of a synthetic dataset."""
    grp = (summary.get("test_groups") or {}).get("measurement_like")
    gen = summary.get("generator") or {}
    if not grp or not gen.get("device"):
        return None
    effects = gen.get("effects") or "default"
    effects = effects if isinstance(effects, str) else ",".join(e for e in effects if e not in CORE)
    paths = " ".join(str(Path(summary["dataset"]) / p) for p in grp["paths"])
    return f"eap diagnose {paths} --device {gen['device']} --effects {effects or 'none'} --out runs/diagnose"


def _pct_or_na(x, fmt: str) -> str:
    """``x`` as a percentage, or "n/a" (a diverged score, a spread of fewer than two folds)."""
    return "n/a" if x is None or not np.isfinite(x) else f"{100 * x:{fmt}} %"


def selection_lines(summary: dict) -> list[str]:
    """How each network was selected and kept (the page): the cross-validation protocol and
    spread where the validation data were few, and the rows that fell back to a parent."""
    from .models.crossval import FOLDS, MIN_WINDOWS
    out = []
    cv = {k: r["validation"]["cross_validation"] for k, r in (summary.get("models") or {}).items()
          if (r.get("validation") or {}).get("cross_validation")}
    if cv:
        first = next(iter(cv.values()))
        out.append(f"Selection protocol: the validation tails hold fewer than {MIN_WINDOWS} independent windows "
                   f"(samples / the output's correlation time), so structures, the keep-over-linear rule and tuning "
                   f"trials were scored by {first['protocol']} ({FOLDS} folds by default: cross-validation costs "
                   "about 2.25 fits instead of one and is used only on such small data). Each network's "
                   "cross-validated score: " + "; ".join(
                       f"{k} {_pct_or_na(c['mean'], '.3g')} ± {_pct_or_na(c['spread'], '.2g')} NRMSE"
                       for k, c in cv.items()) + ".")
    else:
        out.append(f"Selection protocol: one validation split — the dataset's validation records, which decide alone, "
                   f"or the last val_fraction of each training record when those hold {MIN_WINDOWS} or more "
                   "independent windows (samples / the output's correlation time; with fewer, 3 rolling-origin folds "
                   "would have been used).")
    for k, r in (summary.get("models") or {}).items():
        if r.get("falls_back_to"):
            own = r["own"]["validation"]["nrmse"]
            out.append(f"{k} validated worse ({100 * own:.3g} % NRMSE) than its parent {r['falls_back_to']} "
                       f"({100 * r['validation']['nrmse']:.3g} %; {r['fallback_evidence']}), so its row and bundle "
                       f"are {r['falls_back_to']}'s.")
        elif r.get("parent_not_better"):
            out.append(f"{k} stays itself: {r['parent_not_better']}.")
    return out


def _report(summary: dict, out: Path) -> None:
    rep = Report("eap train-compare", f"dataset {summary['dataset']}", output=summary.get("output"),
                 provenance={"dataset hash": summary["dataset_hash"][:16], "fs": f"{summary['fs_Hz']:g} Hz"})
    rep.paragraph(__doc__.strip().split("\n\n")[0])
    rep.table(page_rows(summary["models"]), caption="free-run RMSE and NRMSE by test group (NRMSE = RMSE / std of the "
                                                     "measurement); vs linear: test NRMSE relative to the linear row",
              missing="the dataset has no record of this group, or the row has nothing to count (physics rows)")
    rep.paragraph(f"Start-up rule: {summary.get('start_up', START_UP)}.")
    for line in selection_lines(summary):
        rep.paragraph(line)
    best = summary["best_heldout"]
    if best:
        rep.lead(f"Best free-run NRMSE on {best.get('group', 'held-out RH')}: {best['model']} "
                 f"{100 * best['nrmse']:.2f} %.")
    lin = summary["models"].get(LINEAR)
    if lin is not None:
        rep.paragraph(f"Linear yardstick: {lin['kind']}, orders chosen on the validation data, free-run test "
                      f"NRMSE {100 * lin['free_run']['test']['nrmse']:.2f} % (its bundle, models/{LINEAR}, runs in "
                      "`eap predict`). vs linear: " + "; ".join(
                          f"{k} {vs_linear_text(r['vs_linear_pct'])}"
                          for k, r in summary["models"].items() if r.get("vs_linear_pct") is not None) + ".")
    for n in notes(summary, diagnosis=diagnose_command(summary), with_shortfalls=False):
        rep.why(n["text"], n["links"])
    findings = [f for r in summary["models"].values() for f in r.get("shortfalls", [])]
    if findings:
        rep.heading("Where a network falls short, and why")
        for f in findings:
            first, *causes = sentences(f)
            rep.paragraph(first)
            rep.bullets(causes)
    tuned = {k: r["tuning"] for k, r in summary["models"].items() if r.get("tuning")}
    if tuned:
        rep.heading("Tuning on the validation data")
        first = next(iter(tuned.values()))
        rep.paragraph(f"{first['n_trials']} trials per model, {first['sampler']}, asked and told in batches of "
                      f"{first['batch']} (the same trials for any worker count); score: {first['score']}. "
                      "The chosen trial's settings were trained again and saved: " + "; ".join(
                          f"{k}: {t.get('rule', 'lowest validation score')}" for k, t in tuned.items()) + ".")
        rep.image(out / "tuning.png", "free-run NRMSE [%] on the validation data of every trial, and the best so far")
        rep.table(tuning_rows(tuned), caption="every trial: its validation score and settings")
    for img, cap in (("error_by_rh.png", "free-run NRMSE [%] by nominal RH level, per model (grey: held-out levels)"),
                     ("bode.png", "small-signal response |H| [mm/V] and phase [°] of each network beside the "
                                  "physics closed form"),
                     ("losses.png", "training curves: √train_loss (dotted) and val_loss (solid), both RMS errors of "
                                    "the normalised output"),
                     *[(f"overlay_{g}.png", f"a {group_label(g, bool(facts.get('rh_pct')))} record: measured and "
                                            "predicted, and the residual of each network")
                       for g, facts in (summary.get("test_groups") or {}).items() if g in GROUP_LABELS]):
        if (out / img).is_file():
            rep.image(out / img, cap)
    rep.json_block(summary, "compare.json")
    rep.write_index(out)
