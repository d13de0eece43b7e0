"""The sentences beside odd numbers (nnmodel/explain.py), on hand-made comparison summaries."""
from nnmodel.explain import notes
from nnmodel.explain import group_facts


def _row(kind, held, ml=None, corr=0.96, n=None, history=None, training=None):
    fr = {"heldout_rh": {"nrmse": held / 100}, "test": {"nrmse": held / 100}}
    if ml is not None:
        fr["measurement_like"] = {"nrmse": ml / 100, "correlation": corr}
    row = {"kind": kind, "n_parameters": n, "free_run": fr, "history": history or [], "training": training or {}}
    if kind == "hybrid":      # a grey box's row, as train-compare writes it: its reference is its physics
        row["reference_start"] = {"reference": "physics", "kept": "network"}
    return row


def _summary(**models):
    return {"physics": {"device": "ip2c_pedot_water", "is_generator": True}, "models": models,
            "test_groups": {"measurement_like": {"records": 2, "rh_pct": [55, 85], "extra_effects": ["nonlinear_charge"],
                                                 "paths": ["test/a.csv", "test/b.csv"]}}}


def test_measurement_like_records_are_explained_with_their_numbers():
    s = _summary(physics=_row("physics simulator (generator)", 0.41, ml=194.0),
                 ff=_row("ff", 3.0, ml=201.0, n=100))
    text = " ".join(n["text"] for n in notes(s, diagnosis="#s-the-diagnosis"))
    assert "2 measurement-like records at RH 55, 85 % were simulated with nonlinear_charge" in text
    assert "194 %–201 %" in text and "the physics simulator itself 194 %" in text
    assert "100 % is the error of predicting the record's mean" in text
    assert "ff (3.00 % on held-out RH) is above the physics row (0.410 %)" in text
    first = notes(s, diagnosis="#s-the-diagnosis")[0]
    assert first["links"] == {"The diagnosis below": "#s-the-diagnosis"}
    cmd = notes(s, diagnosis="eap diagnose test/a.csv --device d")[0]["text"]
    assert cmd.endswith("To find the missing effect: eap diagnose test/a.csv --device d")


def test_nothing_odd_no_note():
    s = _summary(physics=_row("physics simulator (generator)", 1.0), ff=_row("ff", 1.05, n=10))
    assert notes(s) == []          # within 10 % of the physics row: nothing to explain


def test_hybrid_behind_its_parents_says_what_its_training_history_shows():
    kept = [{"epoch": -1, "val_loss": 0.01}, {"epoch": 0, "train_loss": 1e-5, "val_loss": 0.02},
            {"epoch": 1, "train_loss": 5e-6, "val_loss": 0.015}]
    s = _summary(physics=_row("physics simulator (generator)", 0.4), narx=_row("narx", 1.0, n=50),
                 hybrid=_row("hybrid", 7.9, n=60, history=kept, training={"epochs": 2, "max_epochs": 2}))
    text = " ".join(n["text"] for n in notes(s))
    assert "The hybrid (7.90 %) is behind its physics part alone (0.400 %) and the best pure network (narx)" in text
    assert "None of its 2 epochs lowered the validation error" in text and "the start was kept" in text
    # the loss scales: a mean square against a root-mean-square
    assert "train_loss 5.00×10⁻⁶ and val_loss 0.0150 (3000×)" in text and "√train_loss = 0.00224" in text
    early = _summary(physics=_row("physics simulator (generator)", 0.4), hybrid=_row(
        "hybrid", 7.9, n=60, history=[{"epoch": -1, "val_loss": 0.05}, {"epoch": 0, "val_loss": 0.02}],
        training={"epochs": 25, "max_epochs": 200}))
    assert "stopped early after 25 of 200 epochs" in " ".join(n["text"] for n in notes(early))


def test_groups_of_a_dataset():
    entries = [{"path": "a.csv", "rh_pct": 70.0019, "extra_effects": ["x"]}, {"path": "b.csv", "rh_pct": 40.0,
                                                                              "extra_effects": []}]
    g = group_facts(entries, lambda e: "measurement_like" if e["extra_effects"] else "train_rh")
    assert g["measurement_like"] == {"records": 1, "rh_pct": [70], "extra_effects": ["x"], "paths": ["a.csv"]}


def test_shortfalls_are_the_notes_about_the_linear_row():
    """A network above the linear row is told once, by its shortfall finding (cause and what
    to do); the page that lists the findings in a section of its own leaves them out."""
    finding = {"finding": "ff: its free-run test error (3.00 %) is above the linear model's (2.00 %)",
               "causes": [{"cause": "too few RH levels", "action": "record at 3 or more RH levels"}]}
    ff = {**_row("ff", 3.0, n=100), "shortfalls": [finding]}
    s = _summary(linear=_row("linear ARX (na=2, nb=4)", 2.0, n=7), ff=ff)
    texts = [n["text"] for n in notes(s)]
    assert texts == ["ff: its free-run test error (3.00 %) is above the linear model's (2.00 %). "
                     "Likely cause: too few RH levels. What to do: record at 3 or more RH levels."]
    assert notes(s, with_shortfalls=False) == []


def test_a_hybrid_that_dropped_its_correction_equals_its_physics_not_behind_it():
    s = _summary(physics=_row("physics simulator (generator)", 0.408), narx=_row("narx", 1.1, n=50),
                 hybrid=_row("hybrid", 0.408 * (1 + 1e-9), n=60))
    text = " ".join(n["text"] for n in notes(s))
    assert "is behind" not in text
    assert "The hybrid (0.408 %) equals its physics part alone" in text and "dropped" in text
