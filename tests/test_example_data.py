"""The example records in data/ are what data/make_examples.py makes (fixed seed), and stay small."""
import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "data"
SHIPPED = sorted(p for p in DATA.rglob("*") if p.is_file() and p.suffix in (".csv", ".yaml"))


def _last_digit(token: str) -> float:
    """One unit in the last decimal place written in ``token`` ("0.0367" -> 1e-4)."""
    token = token.replace(",", ".")
    return 10.0 ** -len(token.split(".")[1]) if "." in token else 1.0


def _same_csv(a: Path, b: Path) -> str | None:
    la, lb = a.read_text(encoding="utf-8").splitlines(), b.read_text(encoding="utf-8").splitlines()
    if len(la) != len(lb) or la[0] != lb[0]:
        return "a different header or number of rows"
    sep = ";" if ";" in la[0] else ","
    for n, (ra, rb) in enumerate(zip(la[1:], lb[1:]), start=2):
        for ta, tb in zip(ra.split(sep), rb.split(sep)):
            # a value may differ by one unit of its last digit (rounding of the last bit of a float)
            if ta != tb and abs(float(ta.replace(",", ".")) - float(tb.replace(",", "."))) > 1.01 * _last_digit(ta):
                return f"line {n}: {ta} != {tb}"
    return None


def test_the_script_makes_the_shipped_files(tmp_path):
    spec = importlib.util.spec_from_file_location("make_examples", DATA / "make_examples.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.make_all(tmp_path)
    made = sorted(p for p in tmp_path.rglob("*") if p.is_file())
    assert [p.relative_to(tmp_path) for p in made] == [p.relative_to(DATA) for p in SHIPPED]
    for new in made:
        old = DATA / new.relative_to(tmp_path)
        if new.suffix == ".yaml":
            assert new.read_text(encoding="utf-8") == old.read_text(encoding="utf-8"), old
        else:
            assert _same_csv(new, old) is None, f"{old.relative_to(ROOT)}: {_same_csv(new, old)}"


def test_the_example_data_stay_small():
    total = sum(p.stat().st_size for p in DATA.rglob("*") if p.is_file())
    assert total < 2_000_000, f"data/ holds {total} bytes"
