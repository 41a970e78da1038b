"""Issue 21, classes 1, 7 and 8 (load expressions): expressions at the parser's limits, singular and
non-finite loads, fibre angles a double cannot place, and scene files with a byte-order mark.

Each refusal is one line naming the key (and, for an expression, the position), with exit status 1, no
traceback, within a timeout, the previous result files byte-identical.  The hypothesis generators at the
end build the expressions that found these bugs: deep, long, overflowing and singular ones.
"""
from __future__ import annotations

import math
import os
import pickle
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import SMALL, previous_set, refused, structured_mesh, unchanged
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_hostile_input import run

from ddsolve.errors import SceneError
from ddsolve.fem.assembly import load_extent
from ddsolve.problem import expressions, scene

EXAMPLES = int(os.environ.get("DDSOLVE_FUZZ_EXAMPLES", "0"))
PAPER = scene.builtin_scenes()["partial-closure"]
KEY = "loads.layer1.top.y"


def refusal(value: str) -> str:
    """The one-line SceneError of the partial-closure scene with ``loads.layer1.top.y = value``."""
    with pytest.raises(SceneError) as error:
        scene.loads(PAPER, [f"{KEY}={value}"], origin="s.toml")
    message = str(error.value)
    assert "\n" not in message and len(message) < 600, message
    assert message.startswith(f"s.toml: {KEY}: "), message
    return message


def scene_with_load(folder: Path, name: str, value: str, prefix: bytes = b"") -> Path:
    """The partial-closure scene with the top load of layer 1 replaced by ``value`` (TOML text)."""
    path = folder / f"{name}.toml"
    path.write_bytes(prefix + PAPER.replace("y = [0.0, -0.078125]", f"y = {value}", 1).encode())
    return path


# --- class 1: the parser's limits (no MPI) -----------------------------------------------------------------
@pytest.mark.parametrize("text, fragment, position", [
    ("(" * 3000 + "x" + ")" * 3000, "nested more than 50 deep", 51),
    ("^".join(["x"] * 3000), "nested more than 50 deep", 101),
    ("-" * 3000 + "x", "nested more than 50 deep", 51),
    ("sin(" * 100 + "x" + ")" * 100, "nested more than 50 deep", 201),
    ("x^1e400", "the number 1e400 is beyond double precision", 3),
    ("x^(1/0)", "the quotient of constants gives inf", 5),
    ("x*10^400", "the power of constants gives inf", 5),
    ("x+exp(1000)", "exp(...) of constants gives inf", 3),
    ("x*sqrt(-1)", "sqrt(...) of constants gives nan", 3),
    ("0/0+x", "the quotient of constants gives nan", 2),
    ("-1e308*10+x", "the product of constants gives -inf", 7),
    ("x^1000000", "a polynomial of degree 1000000, above the 100", 1),
    ("x^1e300", "a polynomial of degree above 1e9", 1),
    ("(x^60)*(y^60)", "a polynomial of degree 120", 1),
    ("x^inf", "unknown name 'inf'", 3),
], ids=lambda value: value[:20] if isinstance(value, str) else None)
def test_expressions_beyond_the_bounds_name_key_and_position(text, fragment, position):
    message = refusal(f'"{text}"')
    assert fragment in message and message.endswith(f"at position {position}"), message


def test_a_megabyte_expression_is_refused_at_once_with_a_short_message():
    text = "+".join(["1.0"] * 262144)  # 1 MB: the tokenizer took 66 s before its traceback
    started = time.perf_counter()
    message = refusal(f'"{text}"')
    assert time.perf_counter() - started < 5.0
    assert f"{len(text)} characters, more than the 10000" in message and "at position 10001" in message


def test_a_long_sum_is_accepted_evaluated_and_sent_to_ranks():
    """3000 terms: a flat chain, no deeper than one term (evaluation and pickling do not recurse through it)."""
    loaded = scene.loads(PAPER, [f'{KEY}="{"+".join(["x"] * 3000)}"'])
    part = pickle.loads(pickle.dumps(loaded)).loads[("layer1", "top")].y
    x = np.linspace(-1.0, 1.0, 5)
    assert part.degree == 1
    np.testing.assert_allclose(part(x, x), 3000 * x, rtol=1e-12)


def test_nesting_up_to_the_bound_is_accepted():
    for text in ("(" * 49 + "x" + ")" * 49, "sin(" * 49 + "x" + ")" * 49, "1-2/(" * 48 + "x" + ")" * 48):
        part = expressions.parse(text)
        pickle.loads(pickle.dumps(part))(np.zeros(3), np.zeros(3))


def test_flat_chains_evaluate_like_the_binary_operators():
    """a - b as a + (-b) and a/b/c as a chain: the same doubles as the left-associative operators."""
    rng = np.random.default_rng(1)
    x, y = rng.normal(size=50), rng.normal(size=50)
    expected = {"x-y-1.5+x*y": x - y - 1.5 + x * y, "x/3/y*2": x / 3.0 / y * 2.0, "2*3*x": (2.0 * 3.0) * x,
                "-x^2/7-y": -np.power(x, 2.0) / 7.0 - y, "1e-3*(x^2 - y)": 1e-3 * (np.power(x, 2.0) - y)}
    for text, values in expected.items():
        assert np.array_equal(expressions.parse(text)(x, y), values), text


def test_a_million_coefficients_are_refused():
    with pytest.raises(SceneError, match=rf"s.toml: {KEY}: 1000000 polynomial coefficients, more than the 101"):
        scene.loads(PAPER.replace("y = [0.0, -0.078125]", "y = [" + "0.0, " * 999999 + "0.0]", 1), origin="s.toml")
    assert scene.loads(PAPER, [f"{KEY}=[{', '.join(['0.0'] * 101)}]"]).loads[("layer1", "top")].y.degree == 100


@pytest.mark.parametrize("value", ["[" * 3000 + "]" * 3000, "{a=" * 3000 + "1" + "}" * 3000], ids=["arrays", "tables"])
def test_toml_nested_too_deeply_is_refused(tmp_path, value):
    with pytest.raises(SceneError, match=r"^--set loads\.layer1\.top\.y=.*: arrays or tables nested too deeply$"):
        scene.loads(PAPER, [f"{KEY}={value}"])
    with pytest.raises(SceneError, match=r"deep\.toml: malformed TOML: arrays or tables nested too deeply$"):
        scene.load(scene_with_load(tmp_path, "deep", value))


# --- classes 7 and 8: singular and infinite loads, fibre angles, byte-order marks (no MPI) -----------------------
@pytest.fixture(scope="module")
def top_edges():
    """The top boundary (y = 1, x in [-1, 1]) of a P1 and a P2 structured mesh."""
    return [(half.points, half.edges("top")) for half in
            (structured_mesh(16, 8, degree=1).upper, structured_mesh(16, 8, degree=2).upper)]


def extent(top_edges, text: str) -> list[float]:
    return [load_extent(points, edges, scene.Load("loads.layer1.top", y=expressions.parse(text)))
            for points, edges in top_edges]


@pytest.mark.parametrize("text", ["1e-4/(x-0.0123)^2", "1/(x-0.0123)", "1/sqrt(sqrt((x-0.0123)^2))",
                                  "1e-4/(x+0.7071)^3", "sin(x)/(x-0.51)^2"])
def test_singular_loads_are_refused_naming_the_key(top_edges, text):
    for points, edges in top_edges:
        with pytest.raises(SceneError, match=r"^loads\.layer1\.top\.y: the load (grows without bound towards|is not "
                                             r"finite at)"):
            load_extent(points, edges, scene.Load("loads.layer1.top", y=expressions.parse(text)))


@pytest.mark.parametrize("text, value", [("exp(1000*x)", "not finite"), ("1/sqrt(x+1)", "not finite"),
                                         ("1/x", "not finite"), ("1e300*1e300*x", "not finite")])
def test_loads_not_finite_on_their_boundary_name_the_key(top_edges, text, value):
    for points, edges in top_edges:
        with pytest.raises(SceneError, match=rf"^loads\.layer1\.top\.y: the load is {value} at \(x, y\)"):
            load_extent(points, edges, scene.Load("loads.layer1.top", y=expressions.parse(text)))


@pytest.mark.parametrize("text, largest", [("sin(pi*x/2)^2", 1.0), ("exp(-((x-0.3)/0.01)^2)", 1.0),
                                           ("1/(x-1.01)^2", 1e4), ("sqrt(x^2)", 1.0), ("sin(1/(x-0.0123))", 1.0),
                                           ("1e-3*(x^2 - y)", 1e-3), ("-0.078125*x", 0.078125)])
def test_bounded_loads_are_accepted_with_their_largest_value(top_edges, text, largest):
    for value in extent(top_edges, text):
        assert value == pytest.approx(largest, rel=1e-3)


def test_fibre_angles_a_double_cannot_place_are_refused():
    orthotropic = "materials.layer2={{E1=140.0, E2=10.0, G12=5.0, nu12=0.3, angle={}}}"
    for angle in ("1e20", "-1e7", "1.5e6"):
        with pytest.raises(SceneError, match=r"^s\.toml: materials\.layer2\.angle must be an angle in degrees of "
                                             r"magnitude at most 1e\+06"):
            scene.loads(PAPER, [orthotropic.format(angle)], origin="s.toml")
    for angle in ("720.0", "-1e6", "30"):
        scene.loads(PAPER, [orthotropic.format(angle)])


def test_a_byte_order_mark_is_dropped(tmp_path):
    plain = scene.load(scene_with_load(tmp_path, "plain", "[0.0, -0.078125]"))
    marked = scene.load(scene_with_load(tmp_path, "marked", "[0.0, -0.078125]", prefix=b"\xef\xbb\xbf"))
    assert marked == plain and marked.text == plain.text


# --- the command line: every example of the issue, end to end -----------------------------------------------
def solve(folder: Path, *arguments: str, timeout: float = 120):
    """``solve -n 2`` into ``folder``/out.h5 over a previous result set; the refusal keeps it."""
    previous = previous_set(folder / "out.h5")
    completed = run("solve", "-n", "2", *arguments, "-o", str(folder / "out.h5"), timeout=timeout, cwd=folder)
    return completed, previous


@pytest.mark.mpi
@pytest.mark.parametrize("value, fragments", [
    ('"' + "(" * 3000 + "x" + ")" * 3000 + '"', ("nested more than 50 deep", "at position 51")),
    ('"' + "^".join(["x"] * 3000) + '"', ("nested more than 50 deep", "at position 101")),
    ('"x^(1/0)"', ("the quotient of constants gives inf", "at position 5")),
    ('"x^1e400"', ("beyond double precision", "at position 3")),
    ('"x^inf"', ("unknown name 'inf'", "at position 3")),
    ('"x^1000000"', ("a polynomial of degree 1000000", "at position 1")),
], ids=["parentheses", "powers", "division-by-zero", "overflow", "inf", "degree"])
def test_cli_expressions_at_the_limits(tmp_path, value, fragments):
    completed, previous = solve(tmp_path, "partial-closure", *SMALL, "--set", f"{KEY}={value}")
    refused(completed, 1, f"partial-closure: {KEY}: bad expression", *fragments)
    assert unchanged(previous)


@pytest.mark.mpi
@pytest.mark.parametrize("name, value, fragments", [
    ("megabyte", '"' + "+".join(["1.0"] * 262144) + '"', ("1048575 characters, more than the 10000",
                                                           "at position 10001")),
    ("million", "[" + "0.0, " * 999999 + "0.0]", ("1000000 polynomial coefficients, more than the 101",)),
], ids=["megabyte", "million"])  # short ids: pytest puts the id in the environment of the runs it starts
def test_cli_huge_loads_in_a_scene_file(tmp_path, name, value, fragments):
    scene_with_load(tmp_path, name, value)
    completed, previous = solve(tmp_path, f"{name}.toml", *SMALL, timeout=60)
    refused(completed, 1, f"{name}.toml: {KEY}: ", *fragments)
    assert unchanged(previous)


@pytest.mark.mpi
def test_cli_a_sum_of_thousands_of_terms_is_solved(tmp_path):
    completed, _ = solve(tmp_path, "partial-closure", *SMALL, "--set", f'{KEY}="{"+".join(["1e-6*x"] * 1400)}"')
    assert completed.returncode == 0 and "Traceback" not in completed.stderr, completed.stderr


@pytest.mark.mpi
@pytest.mark.parametrize("value, fragment", [
    ('"1e-4/(x-0.0123)^2"', "the load grows without bound towards (x, y) = (0.0123, 1)"),
    ('"exp(1000*x)"', "the load is not finite at (x, y) = (1, 1)"),
])
def test_cli_singular_and_infinite_loads_name_the_key(tmp_path, value, fragment):
    completed, previous = solve(tmp_path, "partial-closure", *SMALL, "--set", f"{KEY}={value}")
    line = refused(completed, 1, f"{KEY}: {fragment}")
    assert "moduli" not in line
    assert unchanged(previous)
    refused(run("reference", "partial-closure", *SMALL, "--set", f"{KEY}={value}", "-o", str(tmp_path / "r.h5"),
                timeout=120), 1, f"{KEY}: {fragment}")


@pytest.mark.mpi
def test_cli_infinite_coefficient_names_the_key(tmp_path):
    completed, previous = solve(tmp_path, "partial-closure", *SMALL, "--set", f"{KEY}=[0.0, -1e400]")
    refused(completed, 1, f"partial-closure: {KEY} must be a finite number")
    assert unchanged(previous)


@pytest.mark.mpi
def test_cli_fibre_angle_of_1e20_degrees(tmp_path):
    completed, previous = solve(tmp_path, "partial-closure", *SMALL, "--set",
                                "materials.layer2={E1=140.0, E2=10.0, G12=5.0, nu12=0.3, angle=1e20}")
    refused(completed, 1, "partial-closure: materials.layer2.angle must be an angle in degrees", "(got 1e+20)")
    assert unchanged(previous)


@pytest.mark.mpi
def test_cli_scene_file_with_a_byte_order_mark_is_solved(tmp_path):
    scene_with_load(tmp_path, "bom", "[0.0, -0.078125]", prefix=b"\xef\xbb\xbf")
    completed, _ = solve(tmp_path, "bom.toml", *SMALL)
    assert completed.returncode == 0 and completed.stderr == "", completed.stderr


# --- fuzzing: the generators that would have found these bugs ------------------------------------------------------
ATOMS = st.sampled_from(["x", "y", "pi", "1", "0", "2.5", "1e308", "1e-320", "1e400", "0.0123", "inf", "nan", "z"])


def _grown(children):
    """One more level: sums, products, quotients, powers, signs, functions, parentheses."""
    pair = st.tuples(children, children)
    return st.one_of(
        pair.map(lambda p: f"{p[0]}+{p[1]}"), pair.map(lambda p: f"{p[0]}-{p[1]}"),
        pair.map(lambda p: f"{p[0]}*{p[1]}"), pair.map(lambda p: f"{p[0]}/{p[1]}"),
        pair.map(lambda p: f"{p[0]}^{p[1]}"), children.map(lambda c: f"-{c}"), children.map(lambda c: f"({c})"),
        st.tuples(st.sampled_from(sorted(expressions.FUNCTIONS)), children).map(lambda p: f"{p[0]}({p[1]})"))


#: Deep (nesting by the thousand), long (sums and power chains of thousands of terms), overflowing
#: (1e400, 10^400, 1/0, x^1e300) and garbled expressions.
EXPRESSIONS = st.one_of(
    st.recursive(ATOMS, _grown, max_leaves=30),
    st.tuples(st.integers(1, 4000), st.sampled_from(["(", "sin(", "-", "+"])).map(
        lambda p: p[1] * p[0] + "x" + (")" * p[0] if p[1].endswith("(") else "")),
    st.tuples(st.integers(1, 5000), st.sampled_from(["+", "*", "^", "/", "-"]), ATOMS).map(
        lambda p: p[1].join([p[2]] * p[0])),
    st.tuples(st.sampled_from(["10^", "x^", "exp(", "1/(", "sqrt("]),
              st.sampled_from(["400", "1e300", "1000000", "0", "-1", "(1/0)", "1e400"])).map(
        lambda p: p[0] + p[1] + (")" if p[0].endswith("(") else "")),
    st.text(alphabet="xy0123456789.e+-*/^() sincoexpqrtπΣ\t", max_size=200),
)


@settings(max_examples=EXAMPLES or 150, deadline=None, derandomize=not EXAMPLES,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(text=EXPRESSIONS)
def test_fuzz_expressions_parse_or_name_the_position(text):
    """Any text: an ExpressionError at a position inside it, or an expression within the bounds that
    pickles, evaluates and has a bounded degree."""
    try:
        part = expressions.parse(text)
    except expressions.ExpressionError as error:
        assert 1 <= error.position <= max(len(text), expressions.MAX_LENGTH) + 1
        assert "\n" not in str(error) and len(str(error)) < 300
        return
    assert len(text) <= expressions.MAX_LENGTH
    assert part.degree is None or part.degree <= expressions.MAX_DEGREE
    x = np.linspace(-1.0, 1.0, 7)
    copy = pickle.loads(pickle.dumps(part))
    assert copy == part
    values = copy(x, x)
    assert values.shape == x.shape


@settings(max_examples=EXAMPLES or 40, deadline=None, derandomize=not EXAMPLES,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(text=EXPRESSIONS, component=st.sampled_from(["x", "y", "pressure"]))
def test_fuzz_scene_loads_refuse_in_one_line_naming_the_key(text, component):
    key = f"loads.layer2.right.{component}"
    try:
        scene.loads(PAPER, [f'{key}="{text}"'], origin="s.toml")
    except SceneError as error:
        message = str(error)
        assert "\n" not in message and len(message) < 600, message
        assert message.startswith(f"s.toml: {key}") or message.startswith("--set"), message


#: Singular loads: a pole of order p (or a root singularity) at a point a of the top boundary, times
#: a smooth factor; and bounded ones with their poles off it.  A pole closer to the node at x = 0 than
#: 1e-16 of the box (the resolution of doubles at its size) is the node's own value, finite.
POLES = st.tuples(st.floats(-0.97, 0.97).filter(lambda a: a == 0.0 or abs(a) > 1e-16),
                  st.sampled_from(["1", "2", "3", "0.5", "1.5"]), st.sampled_from(["1", "1e-4", "sin(x)+2", "exp(x)"]))


@settings(max_examples=EXAMPLES or 30, deadline=None, derandomize=not EXAMPLES)
@given(pole=POLES)
def test_fuzz_singular_loads_are_refused(top_edges, pole):
    a, order, factor = pole
    text = f"({factor})/sqrt(((x-({a!r}))^2)^{order})"  # |x - a|^-order
    for points, edges in top_edges:
        with pytest.raises(SceneError, match=r"^loads\.layer1\.top\.y: the load (grows without bound|is not finite)"):
            load_extent(points, edges, scene.Load("loads.layer1.top", y=expressions.parse(text)))


@settings(max_examples=EXAMPLES or 30, deadline=None, derandomize=not EXAMPLES)
@given(pole=POLES, away=st.floats(0.05, 10.0))
def test_fuzz_loads_with_poles_off_the_boundary_are_accepted(top_edges, pole, away):
    a, order, factor = pole
    text = f"({factor})/sqrt(((x-({a!r}))^2+{away!r}^2)^{order})"  # the pole at distance `away` from y = 1
    for value in extent(top_edges, text):
        assert math.isfinite(value) and value > 0.0
