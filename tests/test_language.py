"""The scene language: parsing, compiling to a Model, and the errors a user sees."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import shapely

from sppl.errors import ModelError, ModelErrors
from sppl.lang import ast, compile_model, load_model, parse
from sppl.model.distributions import Categorical, Gamma, Normal, Uniform
from sppl.model.domains import Finite, Interval, Periodic, Positive, Real
from sppl.model.likelihoods import Gaussian
from sppl.model.types import InferenceSettings

MODELS = Path(__file__).resolve().parent.parent / "models"

# A small valid model that the error tests break one line at a time.
BASE = """\
colours {
    red  = rgb(1, 0, 0)
    blue = rgb(0, 0, 1)
}
let spread = 2
class block {
    count ~ poisson(1.5)
    x : real ~ normal(0, spread)
    y : real ~ normal(0, spread)
    w : positive ~ gamma(2, 0.5)
    c : colour ~ categorical(red, blue)
    geometry box(w, w, w) at (x, y) colour c
}
"""


def edited(old: str, new: str) -> str:
    assert old in BASE, old
    return BASE.replace(old, new, 1)


def errors(text: str) -> list[ModelError]:
    with pytest.raises(ModelError) as info:
        compile_model(text, "test.scn")
    error = info.value
    return error.errors if isinstance(error, ModelErrors) else [error]


def only_error(text: str) -> ModelError:
    found = errors(text)
    assert len(found) == 1, "\n".join(str(e) for e in found)
    return found[0]


def position(text: str, needle: str, occurrence: int = 1) -> tuple[int, int]:
    """The 1-based (line, column) of the n-th occurrence of ``needle`` in ``text``.

    ``needle`` may be written ``context>>target`` to find ``target`` after ``context``.
    """
    context, _, target = needle.rpartition(">>")
    index = text.index(context) + len(context) - 1 if context else -1
    needle = target
    for _ in range(occurrence):
        index = text.index(needle, index + 1)
    line = text.count("\n", 0, index) + 1
    return line, index - (text.rfind("\n", 0, index) + 1) + 1


def assert_error_at(
    error: ModelError, text: str, needle: str, message: str, occurrence: int = 1
) -> None:
    """The error says ``message``, points at ``needle`` and shows that line with a caret."""
    assert message in error.message, error.message
    line, column = position(text, needle, occurrence)
    assert (error.span.line, error.span.column) == (line, column), str(error)
    assert error.path == "test.scn"
    shown = str(error).splitlines()
    assert shown[0].startswith(f"test.scn:{line}:{column}: ")
    assert shown[1].endswith(text.splitlines()[line - 1])
    caret = shown[2]
    assert caret.index("^") - caret.index("|") - 2 == column - 1
    assert shown[1].index("|") == caret.index("|")


# ---- shapes.scn -----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def shapes():
    return load_model(MODELS / "shapes.scn")


def test_shapes_has_three_classes_with_their_parameters(shapes):
    assert shapes.class_names == ("cube", "cone", "sphere")
    assert shapes.object_class("cube").parameter_names == ("x", "y", "a", "s", "c")
    assert shapes.object_class("cone").parameter_names == ("x", "y", "r", "h", "c")
    assert shapes.object_class("sphere").parameter_names == ("x", "y", "r", "c")
    assert all(c.rate == 1.0 for c in shapes.classes)
    assert shapes.path == MODELS / "shapes.scn"
    assert shapes.source == (MODELS / "shapes.scn").read_text()


def test_shapes_domains_and_priors(shapes):
    cube = shapes.object_class("cube")
    x, a, s, c = (cube.parameter(n) for n in "xasc")
    assert x.domain == Real() and x.prior == Normal(0.0, 2.5)
    assert a.domain == Periodic(-math.pi / 4, math.pi / 4)
    assert a.prior == Uniform(-math.pi / 4, math.pi / 4)
    # gamma's second positional argument is the scale: mean size 2 * 1/3.
    assert s.domain == Positive() and s.prior == Gamma(2.0, 1.0 / 3.0)
    assert c.domain == Finite(("red", "green", "blue"))
    assert c.prior == Categorical(("red", "green", "blue"), (1 / 3, 1 / 3, 1 / 3))
    assert not c.continuous and x.continuous


def test_shapes_steps(shapes):
    scales = {
        (cls.name, p.name): p.proposal_scale for cls in shapes.classes for p in cls.parameters
    }
    assert scales["cube", "x"] == 0.1
    assert scales["cube", "s"] == 0.05
    assert scales["cone", "h"] == 0.05
    assert scales["sphere", "r"] == 0.05
    assert scales["cube", "c"] == 0.1  # no step given: the default


def test_shapes_sensors_render_and_inference(shapes):
    assert set(shapes.sensors) == {"image", "depth"}
    image = shapes.sensors["image"]
    assert image.kind == "image" and image.likelihood == "gaussian"
    (sigma,) = image.noise
    assert sigma.name == "sigma" and sigma.domain == Positive()
    assert sigma.prior == Gamma(2.0, 0.05) and sigma.proposal_scale == 0.005
    assert shapes.sensors["depth"].noise[0].proposal_scale == 0.01
    assert shapes.render.background == (0.5, 0.5, 0.5)
    assert shapes.render.ambient == 0.35
    assert shapes.render.light == (0.4, -0.3, 1.0)
    assert shapes.inference.p_jump == pytest.approx(1)
    assert shapes.no_overlap
    assert shapes.colours["green"] == (0.15, 0.70, 0.20)


def test_every_model_file_compiles():
    for path in MODELS.glob("*.scn"):
        assert load_model(path).classes


# ---- geometry -------------------------------------------------------------------------------


def test_cube_part_maps_unit_box_corners(shapes):
    cube = shapes.object_class("cube")
    (part,) = cube.parts({"x": 1.0, "y": 2.0, "a": math.pi / 2, "s": 2.0, "c": "blue"})
    assert part.primitive == "box"
    assert part.colour == shapes.colours["blue"]
    # The unit box's top corner (1/2, 1/2, 1) is scaled to (1, 1, 2), turned a quarter
    # counter-clockwise to (-1, 1, 2) and moved by (1, 2, 0).
    corner = part.matrix @ np.array([0.5, 0.5, 1.0, 1.0])
    np.testing.assert_allclose(corner, [0.0, 3.0, 2.0, 1.0], atol=1e-12)
    base_centre = part.matrix @ np.array([0.0, 0.0, 0.0, 1.0])
    np.testing.assert_allclose(base_centre, [1.0, 2.0, 0.0, 1.0])


def test_footprint_of_a_rotated_box():
    model = compile_model(
        """
        class slab {
            count ~ poisson(1)
            x : real ~ normal(0, 1)
            geometry box(2, 1, 0.5) at (x, -1) rotate pi/2 colour rgb(0.2, 0.2, 0.2)
        }
        """
    )
    footprint = shapely.Polygon(model.object_class("slab").footprint({"x": 1.0}))
    # 2 m wide along x before the quarter turn, so 2 m along y after it.
    assert footprint.area == pytest.approx(2.0)
    np.testing.assert_allclose(footprint.bounds, (0.5, -2.0, 1.5, 0.0), atol=1e-12)


def test_a_new_cylinder_class_needs_no_python():
    model = compile_model(
        BASE
        + """
class barrel {
    count ~ poisson(0.5)
    x : real ~ normal(0, spread)
    y : real ~ normal(0, spread)
    r : interval(0.1, 1) ~ uniform(0.2, 0.5)
    h : positive ~ gamma(3, rate=2)
    geometry cylinder(r, h) at (x, y, 0.1) colour red
}
"""
    )
    barrel = model.object_class("barrel")
    assert model.class_names == ("block", "barrel")
    assert barrel.parameter("h").prior == Gamma(3.0, 0.5)  # rate 2 is scale 1/2
    assert barrel.parameter("r").domain == Interval(0.1, 1.0)
    (part,) = barrel.parts({"x": 1.0, "y": -1.0, "r": 0.3, "h": 2.0})
    expected = np.diag([0.3, 0.3, 2.0, 1.0])
    expected[:3, 3] = (1.0, -1.0, 0.1)
    np.testing.assert_allclose(part.matrix, expected)
    assert part.primitive == "cylinder" and part.colour == (1.0, 0.0, 0.0)
    values = barrel.sample_prior(np.random.default_rng(0))
    assert math.isfinite(barrel.log_prior(values))


def test_several_geometry_lines_make_a_composite():
    model = compile_model(
        """
        colours { wood = rgb(0.5, 0.3, 0.1) }
        class table {
            count ~ poisson(1)
            x : real ~ normal(0, 1)
            top : positive ~ gamma(2, 0.5)
            geometry box(1, 1, 0.05) at (x, 0, top) colour wood
            geometry cylinder(0.05, top) at (x, 0) colour wood
        }
        """
    )
    parts = model.object_class("table").parts({"x": 2.0, "top": 0.7})
    assert [p.primitive for p in parts] == ["box", "cylinder"]
    np.testing.assert_allclose(parts[0].matrix[:3, 3], (2.0, 0.0, 0.7))
    np.testing.assert_allclose(np.diag(parts[1].matrix), (0.05, 0.05, 0.7, 1.0))


def test_expressions_and_weighted_categorical():
    model = compile_model(
        edited("let spread = 2", "let spread = max(1, sqrt(2^2) * 3 - -1) / abs(-2)")
        .replace("categorical(red, blue)", "categorical(red: 3, blue: 1)")
        .replace("gamma(2, 0.5)", "gamma(2, scale=2 ** -1)")
    )
    block = model.object_class("block")
    assert block.parameter("x").prior == Normal(0.0, 3.5)
    assert block.parameter("w").prior == Gamma(2.0, 0.5)
    assert block.parameter("c").prior.probs == (0.75, 0.25)


@pytest.mark.parametrize(
    "expression, value",
    [
        ("-2^2 + 5", 1.0),  # the power binds tighter than the minus
        ("2^3^2 / 2**8", 2.0),  # and groups to the right
        ("10 - 4 - 3", 3.0),
        ("12 / 3 / 2", 2.0),
        ("min(3, 1.5, 2) + max(0, -1)", 1.5),
        ("cos(pi) + exp(log(3))", 2.0),
        ("abs(-2) * sqrt(4) + tan(0) + sin(0)", 4.0),
    ],
)
def test_constant_expressions(expression, value):
    model = compile_model(edited("poisson(1.5)", f"poisson({expression})"))
    assert model.object_class("block").rate == pytest.approx(value)


def test_keywords_can_be_parameter_names():
    model = compile_model(
        """
        colours { red = rgb(1, 0, 0) }
        class thing {
            count ~ poisson(1)
            at : real ~ normal(0, 1)
            step : positive ~ gamma(2, 1)
            colour : colour ~ categorical(red)
            rotate : real ~ normal(0, 1)
            geometry sphere(step) at (at, 0) rotate rotate colour colour
        }
        inference { step step = 0.3 }
        """
    )
    thing = model.object_class("thing")
    assert thing.parameter_names == ("at", "step", "colour", "rotate")
    assert thing.parameter("step").proposal_scale == 0.3


def test_american_spellings_comments_and_number_forms():
    model = compile_model(
        """
        colors { grey = (0.5, 0.5, 0.5) }  # a tuple works as well as rgb(...)
        let k = -2^2 + 2**3 + .5 + 1e-1    # -4 + 8 + 0.6
        class pebble {
            count ~ poisson(k)
            c : color ~ categorical(grey)
            geometry sphere(0.1) color c
        }
        """
    )
    pebble = model.object_class("pebble")
    assert pebble.rate == pytest.approx(4.6)
    assert pebble.parts({"c": "grey"})[0].colour == (0.5, 0.5, 0.5)


def test_qualified_step_wins_and_jump_weights():
    model = compile_model(
        BASE + "inference {\n    step block.x = 0.5\n    step x = 0.2\n"
        "    jump_weights birth = 2, death = 2\n}\n"
    )
    block = model.object_class("block")
    assert block.parameter("x").proposal_scale == 0.5
    assert block.parameter("y").proposal_scale == 0.1
    assert model.inference.jump_weights == {
        **InferenceSettings().jump_weights, "birth": 2.0, "death": 2.0
    }
    assert model.inference.p_jump == pytest.approx(1 / 20)  # the default


def test_compile_model_from_a_string_has_no_path():
    model = compile_model(BASE)
    assert model.path is None and model.source == BASE
    assert not model.no_overlap and model.sensors == {}


def test_parse_gives_an_ast_with_positions():
    program = parse(BASE, "test.scn")
    block = program.statements[2]
    assert isinstance(block, ast.ClassDef) and block.name.text == "block"
    assert (block.span.line, block.span.column) == (6, 1)
    geometry = block.body[-1]
    assert isinstance(geometry, ast.Geometry)
    assert [m.keyword for m in geometry.modifiers] == ["at", "colour"]


# ---- syntax errors --------------------------------------------------------------------------


def test_syntax_error_names_what_was_expected():
    text = edited("normal(0, spread)", "normal(0, spread")
    error = only_error(text)
    assert type(error) is ModelError
    assert_error_at(error, text, "y : real", "unexpected name `y`; expected `)` or `,`")


def test_missing_closing_brace():
    text = BASE.rstrip().rstrip("}")
    error = only_error(text)
    assert error.message.startswith("the file ends too early; expected ")
    assert "`}`" in error.message
    assert (error.span.line, error.span.column) == (12, 45)  # just after the last token


def test_missing_tilde():
    text = edited("x : real ~ normal", "x : real normal")
    assert_error_at(only_error(text), text, "normal(0, spread)", "expected `~`")


def test_unexpected_character():
    text = edited("let spread = 2", "let spread = 2 $")
    assert_error_at(only_error(text), text, "$", "unexpected character `$`")


def test_missing_brace_before_the_next_class():
    text = (
        edited(
            "    geometry box(w, w, w) at (x, y) colour c\n}\n",
            "    geometry box(w, w, w) at (x, y) colour c\n",
        )
        + "class other {\n}\n"
    )
    error = only_error(text)
    assert_error_at(error, text, "class other", "unexpected `class`; expected ")
    assert "`}`" in error.message


def test_incomplete_expression():
    text = edited("let spread = 2", "let spread = (2 * )")
    assert_error_at(only_error(text), text, "2 * >>)", "unexpected `)`; expected an expression")


# ---- semantic errors ------------------------------------------------------------------------


def test_unknown_name_with_did_you_mean():
    text = edited("normal(0, spread)", "normal(0, sprad)")
    error = only_error(text)
    assert_error_at(error, text, "sprad", "unknown name `sprad`")
    assert error.hint == "did you mean `spread`?"
    assert "(did you mean `spread`?)" in str(error).splitlines()[0]


@pytest.mark.parametrize(
    "old, new, needle, message, hint",
    [
        ("normal(0, spread)", "nromal(0, spread)", "nromal", "unknown distribution", "normal"),
        ("box(w, w, w)", "bx(w, w, w)", "bx", "unknown primitive `bx`", "box"),
        ("x : real", "x : reel", "reel", "unknown domain `reel`", "real"),
        ("categorical(red, blue)", "categorical(red, bleu)", "bleu", "unknown colour", "blue"),
        ("gamma(2, 0.5)", "gamma(2, rat=2)", "rat=", "`gamma` has no argument `rat`", "rate"),
        ("box(w, w, w)", "box(w, w, sqr(w))", "sqr", "unknown function `sqr`", "sqrt"),
    ],
)
def test_misspellings(old, new, needle, message, hint):
    text = edited(old, new)
    error = only_error(text)
    assert_error_at(error, text, needle, message)
    assert error.hint == f"did you mean `{hint}`?"


@pytest.mark.parametrize(
    "old, new, needle, message",
    [
        (
            "normal(0, spread)",
            "normal(0, spread, 1)",
            "normal(0, spread, 1)",
            "wrong number of arguments to `normal`: expected normal(mu, sigma), got 3 arguments",
        ),
        (
            "gamma(2, 0.5)",
            "gamma(2)",
            "gamma(2)",
            "expected gamma(shape, scale) or gamma(shape, rate=...), got 1 argument",
        ),
        (
            "box(w, w, w)",
            "box(w, w)",
            "box(w, w)",
            "wrong number of arguments to `box`: expected box(width, depth, height), got 2",
        ),
        ("box(w, w, w)", "sphere(w, w)", "sphere(w, w)", "expected sphere(radius), got 2"),
        ("x : real", "x : interval(0)", "interval(0)", "`interval` needs bounds"),
    ],
)
def test_wrong_number_of_arguments(old, new, needle, message):
    text = edited(old, new)
    assert_error_at(only_error(text), text, needle, message)


@pytest.mark.parametrize(
    "old, new, needle, message",
    [
        (
            "x : real ~ normal(0, spread)",
            "x : positive ~ normal(0, spread)",
            "normal(0, spread)",
            "the prior `normal(0, spread)` does not fit the domain positive",
        ),
        (
            "x : real ~ normal(0, spread)",
            "x : interval(0, 1) ~ uniform(-1, 0.5)",
            "uniform(-1, 0.5)",
            "does not fit the domain interval(0, 1)",
        ),
        (
            "x : real ~ normal(0, spread)",
            "x : periodic(0, pi) ~ uniform(0, 4)",
            "uniform(0, 4)",
            "does not fit the domain periodic(0, 3.14159)",
        ),
        (
            "x : real ~ normal(0, spread)",
            "x : periodic(0, pi) ~ normal(1, 1)",
            "normal(1, 1)",
            "does not fit the domain periodic",
        ),
        (
            "c : colour ~ categorical(red, blue)",
            "c : real ~ categorical(red, blue)",
            "categorical(red, blue)",
            "categorical draws names",
        ),
        (
            "c : colour ~ categorical(red, blue)",
            "c : colour ~ uniform(0, 1)",
            "colour ~",
            "a colour parameter needs a categorical prior",
        ),
        (
            "categorical(red, blue)",
            "categorical(red, spread)",
            "red, >>spread",
            "`spread` is a constant, not a palette colour",
        ),
        (
            "w : positive ~ gamma(2, 0.5)",
            "w : positive ~ gamma(2, -1)",
            "-1",
            "the scale of gamma must be positive",
        ),
        ("normal(0, spread)", "normal(0, 1 - 1)", "1 - 1", "the standard deviation of normal"),
    ],
)
def test_prior_must_fit_its_domain(old, new, needle, message):
    text = edited(old, new)
    # Breaking c's prior also breaks `colour c`: only the first error is this test's business.
    assert_error_at(errors(text)[0], text, needle, message)


def test_gamma_on_real_and_uniform_inside_periodic_are_fine():
    model = compile_model(
        edited("x : real ~ normal(0, spread)", "x : real ~ gamma(2, 1)").replace(
            "y : real ~ normal(0, spread)", "y : periodic(-pi, pi) ~ uniform(-pi/2, pi/2)"
        )
    )
    assert model.object_class("block").parameter("y").domain == Periodic(-math.pi, math.pi)


@pytest.mark.parametrize(
    "old, new, needle, message",
    [
        (
            "blue = rgb(0, 0, 1)",
            "red = rgb(0, 0, 1)",
            "red = rgb(0, 0, 1)",
            "`red` is already defined on line 2",
        ),
        (
            "let spread = 2",
            "let spread = 2\nlet spread = 3",
            "spread = 3",
            "`spread` is already defined on line 5",
        ),
        ("let spread = 2", "let pi = 3", "pi", "`pi` is built in"),
        (
            "y : real",
            "x : real",
            "x : real ~ normal(0, spread)\n    w",
            "class `block` already has a parameter or derived quantity `x` (line 8)",
        ),
        ("y : real", "spread : real", "spread : real", "`spread` is already defined on line 5"),
    ],
)
def test_duplicate_names(old, new, needle, message):
    text = edited(old, new)
    assert_error_at(errors(text)[0], text, needle, message)


def test_duplicate_class():
    text = BASE + BASE[BASE.index("class") :]
    error = only_error(text)
    assert_error_at(error, text, "block", "class `block` is already defined on line 6", 2)
    assert error.span.line == 14


def test_use_before_definition():
    text = "let a = b + 1\nlet b = 2\n" + BASE
    assert_error_at(only_error(text), text, "b + 1", "`b` is used before its definition on line 2")
    text = "let a = a + 1\n" + BASE
    assert_error_at(only_error(text), text, "a + 1", "`a` is used in its own definition")


def test_inside_a_class_declarations_may_come_in_any_order():
    text = edited(
        "    c : colour ~ categorical(red, blue)\n    geometry box(w, w, w) at (x, y) colour c",
        "    geometry box(w, w, w) at (x, y) colour c\n    c : colour ~ categorical(red, blue)",
    )
    assert compile_model(text).object_class("block").parameter_names[-1] == "c"


def test_colour_used_before_the_palette():
    text = BASE[BASE.index("let") :] + BASE[: BASE.index("let")]
    found = errors(text)
    assert [e.message for e in found] == [
        "`red` is used before its definition on line 11",
        "`blue` is used before its definition on line 12",
    ]


def test_noise_prior_may_not_use_a_parameter():
    text = BASE + (
        "sensor image {\n    likelihood gaussian\n    sigma : positive ~ gamma(2, tau)\n"
        "    tau : positive ~ gamma(2, 1)\n}\n"
    )
    first, second = errors(text)
    assert_error_at(first, text, "tau)", "a noise prior may use constants only")
    assert_error_at(second, text, "tau :", "the gaussian likelihood has no noise parameter `tau`")


def test_model_without_classes():
    error = only_error("let a = 1\n")
    assert error.message == "the model declares no object classes"
    assert (error.span.line, error.span.column) == (1, 1)


def test_class_without_geometry():
    text = edited("    geometry box(w, w, w) at (x, y) colour c\n", "")
    assert_error_at(only_error(text), text, "block", "class `block` has no geometry")


def test_class_without_count():
    text = edited("    count ~ poisson(1.5)\n", "")
    error = only_error(text)
    assert_error_at(error, text, "block", "class `block` has no count")
    assert "count ~ poisson(rate)" in error.hint


def test_count_needs_a_poisson_prior():
    text = edited("poisson(1.5)", "normal(1.5, 1)")
    assert_error_at(only_error(text), text, "normal(1.5", "needs a poisson prior")


def test_geometry_needs_a_colour_and_takes_each_modifier_once():
    text = edited(" colour c\n", "\n")
    assert_error_at(only_error(text), text, "geometry", "a geometry line needs a colour")
    text = edited(" colour c\n", " colour c rotate 1 rotate 2\n")
    assert_error_at(only_error(text), text, "rotate 2", "`rotate` is given twice")


def test_colour_of_geometry_must_be_a_colour():
    text = edited("colour c\n", "colour x\n")
    assert_error_at(only_error(text), text, "x\n", "`x` is a parameter, not a colour")


@pytest.mark.parametrize(
    "block, needle, message, hint",
    [
        ("render { ambiant = 0.3 }", "ambiant", "unknown render setting `ambiant`", "ambient"),
        ("inference { p_jmp = 0.1 }", "p_jmp", "unknown inference setting `p_jmp`", "p_jump"),
        ("inference { jump_weights brith = 1 }", "brith", "unknown jump `brith`", "birth"),
        (
            "sensor imag { likelihood gaussian sigma : positive ~ gamma(2, 1) }",
            "imag",
            "unknown sensor `imag`",
            "image",
        ),
        ("constraint no_overlop", "no_overlop", "unknown constraint `no_overlop`", "no_overlap"),
    ],
)
def test_unknown_settings(block, needle, message, hint):
    text = BASE + block + "\n"
    error = only_error(text)
    assert_error_at(error, text, needle, message)
    assert error.hint == f"did you mean `{hint}`?"


@pytest.mark.parametrize(
    "step, needle, message",
    [
        ("step z = 0.1", "z", "no parameter `z` to step"),
        ("step block.q = 0.1", "q", "no parameter `q` in `block` to step"),
        ("step blok.x = 0.1", "blok", "no class or sensor is called `blok`"),
        ("step c = 0.1", "c =", "`c` is categorical"),
        ("step x = -1", "-1", "a step must be positive"),
    ],
)
def test_bad_steps(step, needle, message):
    text = BASE + "inference {\n    " + step + "\n}\n"
    assert_error_at(only_error(text), text, needle, message)


def test_step_did_you_mean():
    error = only_error(BASE + "inference { step blok.x = 0.1 }\n")
    assert error.hint == "did you mean `block`?"


def test_sensor_errors():
    text = BASE + "sensor image {\n    sigma : positive ~ gamma(2, 0.1)\n}\n"
    assert_error_at(only_error(text), text, "image", "sensor `image` has no likelihood")
    text = (
        BASE + "sensor image {\n    likelihood gaussian\n    sigma : positive ~ normal(0, 1)\n}\n"
    )
    assert_error_at(only_error(text), text, "normal(0, 1)", "does not fit the domain positive")


class _ScaledGaussian(Gaussian):
    """A likelihood with an option, registered for the tests below."""

    noise_parameters = ("sigma",)

    def __init__(self, gain: float = 1.0, offset: float = 0.0) -> None:
        self.gain, self.offset = gain, offset


@pytest.fixture(autouse=True)
def _scaled_gaussian(registered):
    registered("scaled_gaussian", _ScaledGaussian)


def test_sensor_options_and_noise_steps():
    model = compile_model(
        BASE + "sensor depth {\n    likelihood scaled_gaussian(gain = 2)\n    offset = 2 * 5\n"
        "    sigma : positive ~ gamma(2, 0.1)\n}\ninference { step depth.sigma = 0.02 }\n"
    )
    depth = model.sensors["depth"]
    assert depth.likelihood == "scaled_gaussian"
    assert depth.options == {"gain": 2.0, "offset": 10.0}
    assert depth.noise[0].proposal_scale == 0.02


def test_all_errors_are_reported_sorted_by_position():
    # Steps are checked after every class is known, so this file's first error is found last.
    text = (
        "inference { step z = 1 }\n"
        + edited("normal(0, spread)", "normal(0, sprad)").replace("box(w, w, w)", "bx(w, w, w)")
        + "render { ambiant = 1 }\n"
    )
    with pytest.raises(ModelErrors) as info:
        compile_model(text, "test.scn")
    assert [e.span.line for e in info.value.errors] == [1, 9, 13, 15]
    assert info.value.span.line == 1
    assert str(info.value).count("test.scn:") == 4


def test_constant_errors_are_reported_where_they_happen():
    text = edited("let spread = 2", "let spread = 1 / (2 - 2)")
    assert_error_at(only_error(text), text, "1 / (2", "division by zero")


def test_geometry_that_fails_for_some_values_raises_a_model_error():
    text = edited("box(w, w, w)", "box(w, w, sqrt(x))")
    block = compile_model(text, "test.scn").object_class("block")
    with pytest.raises(ModelError) as info:
        block.parts({"x": -1.0, "y": 0.0, "w": 1.0, "c": "red"})
    assert info.value.span.line == 12


def test_load_model_of_a_missing_file(tmp_path):
    with pytest.raises(ModelError) as info:
        load_model(tmp_path / "nothing.scn")
    assert "cannot read the model file" in str(info.value)


def test_mangled_models_only_ever_raise_model_errors():
    """Whatever the edit, the user sees a ModelError with a position, never a traceback."""
    source = (MODELS / "shapes.scn").read_text()
    pieces = [
        "(",
        ")",
        "{",
        "}",
        ",",
        ":",
        "~",
        "=",
        "-",
        "^",
        "x",
        "colour",
        "at",
        "class",
        "0",
        "1e999",
        "pi",
        "step",
        ".",
        "#",
        "\n",
        "rgb(",
        "let",
        "geometry",
        "red",
    ]
    rng = np.random.default_rng(0)
    for _ in range(300):
        text = source
        for _ in range(rng.integers(1, 4)):
            at = int(rng.integers(len(text)))
            if rng.random() < 0.5:
                text = text[:at] + text[at + int(rng.integers(1, 8)) :]
            else:
                text = text[:at] + pieces[int(rng.integers(len(pieces)))] + text[at:]
        try:
            compile_model(text, "test.scn")
        except ModelError as e:
            assert e.span is not None and e.path == "test.scn" and e.source == text
