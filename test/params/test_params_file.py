"""`params.params_file`: a bad params file read offline is refused in one bounded line naming
it, whatever it holds (an alias bomb, an integer of 5000 digits), and mutated and random
text give nothing but that ValueError (hypothesis). (config/default.yaml read so:
test_settings.py.)"""

import re
from pathlib import Path

import pytest
from fuzz_text import mutated
from hypothesis import HealthCheck, given
from hypothesis import settings as settings_
from hypothesis import strategies as st

from ssa_fusion.core.base.quoting import MAX_MESSAGE
from ssa_fusion.params.params_file import load_params_file

CONFIG = Path(__file__).resolve().parents[2] / "config" / "default.yaml"


def test_params_file_errors_name_the_file_and_value(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("filter:\n  ros__parameters:\n    motion_model: sgp4\n")
    with pytest.raises(ValueError, match=r"bad\.yaml.*motion_model' = 'sgp4'"):
        load_params_file(bad)
    mixed = tmp_path / "mixed.yaml"
    mixed.write_text("filter:\n  ros__parameters:\n    kind: position\n"
                     "surrogate:\n  ros__parameters:\n    kind: range_az_el\n")
    with pytest.raises(ValueError, match="disagree on 'kind'"):
        load_params_file(mixed)
    with pytest.raises(ValueError, match="cannot read params file"):
        load_params_file(tmp_path / "missing.yaml")


@pytest.mark.parametrize(("text", "says"), [
    ("filter:\n  ros__parameters:\n    q: .nan\n", "filter: parameter 'q' = nan: must be"),
    ("filter:\n  ros__parameters:\n    q: [1, 2]\n", "filter: parameter 'q' = [1, 2]"),
    ("filter:\n  ros__parameters:\n    qq: 1.0\n", "filter: 'qq' is not a parameter of filter"),
    # a bool is no number (Python's True is 1: q: true was taken as 1.0)
    ("filter:\n  ros__parameters:\n    q: true\n", "filter: parameter 'q' = True: must be"),
    ("surrogate:\n  ros__parameters:\n    delays: true\n", "parameter 'delays' = True"),
    ("surrogate:\n  ros__parameters:\n    delays: -3\n", "surrogate: parameter 'delays' = -3"),
    ("[" * 50000 + "]" * 50000, "nested too deeply or too large to read"),
])
def test_a_params_file_offline_gets_the_nodes_checks(tmp_path, text, says):
    """`report`/`replay --params-file` judged the file less than the nodes do: a NaN q gave
    a garbage table with exit 0, deep nesting a RecursionError traceback."""
    path = tmp_path / "p.yaml"
    path.write_text(text)
    with pytest.raises(ValueError, match=re.escape(says)):
        load_params_file(path)


# ------------------------------------------------------------------------------------------
# hostile params files: bounded time, memory and message (named cases), and fuzzing
# ------------------------------------------------------------------------------------------
BOMB = "&l0 [lol, lol, lol, lol, lol, lol, lol, lol, lol], " + ", ".join(
    f"&l{i} [{', '.join([f'*l{i - 1}'] * 9)}]" for i in range(1, 12))
"""YAML flow items whose last list holds 9^11 (3e10) items by aliases: 500 bytes of text."""


def filter_params(line: str) -> str:
    return f"filter:\n  ros__parameters:\n    {line}\n"


@pytest.mark.parametrize(("text", "says"), [
    # the repr of an alias bomb in the message: 312 MB for 9^8 items, 9 s, 750 MB
    (filter_params(f"p0_sigma: [{BOMB}]"), "filter: parameter 'p0_sigma' = [['lol', 'lol',"),
    # str() of the value before reading it as stations: the same, without end
    (filter_params(f"station: [{BOMB}]"), "parameter 'station' = [['lol', 'lol', 'lol', 'lol', "
                                          "...], [['lol', 'lol', 'lol'...: must name a station"),
    (filter_params(f"sites: {{a: [{BOMB}]}}"), "parameter 'sites' = {'a': [["),
    # an int beyond a float: OverflowError out of the parameter check
    (filter_params(f"q: {10**400}"), "parameter 'q' = <integer of 1329 bits>: must be"),
    # an int of 5000 digits: PyYAML's int() raised a bare ValueError without the file
    (filter_params("q: " + "9" * 5000), "not YAML PyYAML can load: ValueError"),
    (filter_params("q: !!float"), "not YAML PyYAML can load: IndexError"),
    (filter_params("k" * 1000 + ": 1"), "filter: 'kkkkkkkkkk"),
    ("filter: {ros__parameters: {q: caf\xe9}}".encode("latin-1"), "cannot read params file"),
])
def test_a_hostile_params_file_is_refused_in_one_bounded_line(tmp_path, text, says):
    import time

    path = tmp_path / "p.yaml"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    t0 = time.perf_counter()
    with pytest.raises(ValueError) as exc:
        load_params_file(path)
    said = str(exc.value)
    assert time.perf_counter() - t0 < 5.0
    assert "\n" not in said and len(said) <= MAX_MESSAGE and str(path) in said, said[:300]
    assert says in said, said


FUZZ = settings_(max_examples=150, deadline=None, derandomize=True,
                 suppress_health_check=[HealthCheck.too_slow])
TOKENS = [": ", "- ", "\n", "  ", "[", "]", "{", "}", ",", "&a ", "*a", "!!float ", "!!binary ",
          ".nan", ".inf", "1e400", "9" * 400, "true", "~", "ros__parameters:", "/**:", "filter:",
          "surrogate:", "kind: ra_dec", "station: nordlys", "sites: config/sites/example.yaml",
          "lift: none", "motion_model: j2", "'", '"', "#", "\t", "\x00", "é", "? ", "<<: "]


@pytest.fixture(scope="module")
def fuzz_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("params_fuzz")


def _only_value_errors(path: Path, text: str) -> None:
    """`load_params_file` gives an estimator or a bounded ValueError naming the file."""
    path.write_text(text, encoding="utf-8", errors="surrogatepass")
    try:
        load_params_file(path)
    except ValueError as exc:
        said = str(exc)
        assert "\n" not in said and len(said) <= MAX_MESSAGE and str(path) in said, said[:300]


@FUZZ
@given(mutated(CONFIG.read_text(), TOKENS))
def test_a_mutated_params_file_gives_an_estimator_or_one_value_error(fuzz_dir, text):
    _only_value_errors(fuzz_dir / "m.yaml", text)


@FUZZ
@given(st.one_of(st.text(max_size=300),
                 st.lists(st.sampled_from(TOKENS), max_size=40).map("".join)))
def test_random_text_gives_an_estimator_or_one_value_error(fuzz_dir, text):
    _only_value_errors(fuzz_dir / "r.yaml", text)
