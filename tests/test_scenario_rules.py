"""The validation rules of ``experiments/scenario.py``, each on a small document written here:
the schema of docs/scenarios.md (its defaults, what is required, the ranges it states), the TOML syntax
of ``--set`` values (toml.io, v1.0.0), and the error messages' promise (the key, the file and line, or the
``--set`` that wrote it). Bounds that docs/scenarios.md does not spell out are the physical ones, with the
reason in a comment (a mass is positive, a tilt between two axes is at most 180 deg).

Quick tier: no robot run, no graph built (the feature check composes a terrain, a few boxes)."""

from __future__ import annotations

import math
import re
import tomllib

import pytest

from cpgsim.experiments import scenario as sc
from cpgsim.experiments.scenario import (
    SCHEMA,
    Field,
    Scenario,
    ScenarioError,
    apply_override,
    dump_toml,
    line_of,
    load,
    parse_value,
    resolve_key,
    validate,
)

BASE = 'name = "t"\nt_end = 2.0\n'


def _doc(text: str, source: str = "s.toml") -> Scenario:
    """``text`` parsed and validated as the file ``source``."""
    s = Scenario(tomllib.loads(text), source, text)
    validate(s)
    return s


def _err(text: str) -> str:
    with pytest.raises(ScenarioError) as info:
        _doc(text)
    return str(info.value)


# -- Field.check: types --------------------------------------------------------------------------------------

def test_a_number_field_takes_ints_and_floats_only_finite():
    f = Field(float)
    assert f.check("k", 3, "") == 3.0 and type(f.check("k", 3, "")) is float
    assert f.check("k", -2.5, "") == -2.5
    for bad, shown in ((True, "bool True"), ("3", "'3'"), ([1], "list [1]"), (None, "NoneType None")):
        with pytest.raises(ScenarioError, match=re.escape(f"k must be a number, got {shown} @")):
            f.check("k", bad, " @")
    for bad in (math.inf, -math.inf, math.nan):
        with pytest.raises(ScenarioError, match=re.escape(f"k must be finite, got {bad} @")):
            f.check("k", bad, " @")


def test_an_integer_field_takes_whole_numbers():
    """A whole float (TOML 2.0) is the integer 2; 2.5, true and "2" are not integers."""
    f = Field(int)
    assert f.check("k", 2.0, "") == 2 and type(f.check("k", 2.0, "")) is int and f.check("k", -4, "") == -4
    for bad, shown in ((2.5, "float 2.5"), (True, "bool True"), ("2", "'2'")):
        with pytest.raises(ScenarioError, match=re.escape(f"k must be an integer, got {shown} @")):
            f.check("k", bad, " @")


@pytest.mark.parametrize("kind, good, bad, phrase", [
    (bool, False, 0, "must be true or false, got int 0"),
    (str, "x", 1, "must be a string, got int 1"),
    (list, [1], "x", "must be a list, got 'x'"),
])
def test_bool_string_and_list_fields(kind, good, bad, phrase):
    f = Field(kind)
    assert f.check("k", good, "") == good
    with pytest.raises(ScenarioError, match=re.escape(f"k {phrase} @")):
        f.check("k", bad, " @")


def test_choices():
    f = Field(str, choices=("a", "b"))
    assert f.check("k", "b", "") == "b"
    with pytest.raises(ScenarioError, match=re.escape("k must be one of a, b, got 'c' @")):
        f.check("k", "c", " @")


def test_range_bounds_at_their_edges():
    """lo inclusive unless strict; hi inclusive; the message says which."""
    inclusive, strict, capped = Field(float, lo=0.0), Field(float, lo=0.0, strict=True), Field(float, hi=180.0)
    assert inclusive.check("k", 0.0, "") == 0.0 and strict.check("k", 1e-300, "") == 1e-300
    assert capped.check("k", 180.0, "") == 180.0 and capped.check("k", -1e9, "") == -1e9
    with pytest.raises(ScenarioError, match=re.escape("k = -0.5 is out of range: must be >= 0 @")):
        inclusive.check("k", -0.5, " @")
    with pytest.raises(ScenarioError, match=re.escape("k = 0.0 is out of range: must be > 0 @")):
        strict.check("k", 0.0, " @")
    with pytest.raises(ScenarioError, match=re.escape("k = 180.5 is out of range: must be <= 180 @")):
        capped.check("k", 180.5, " @")
    ints = Field(int, lo=1, hi=3)
    assert [ints.check("g", g, "") for g in (1, 2, 3)] == [1, 2, 3]
    for g in (0, 4):
        with pytest.raises(ScenarioError, match="out of range"):
            ints.check("g", g, "")


# -- the schema's ranges and defaults (docs/scenarios.md) ------------------------------------------------

# (key, lowest allowed, a value below it or None, highest allowed or None, a value above it or None); why:
RANGES = [
    ("t_end", 1e-9, 0.0, None, None),  # simulated time: positive
    ("seed", 0, -1, None, None),  # a seed is a natural number
    ("robot.body_mass", 1e-9, 0.0, None, None),  # geometry overrides (m, kg): positive
    ("robot.stance_width", 1e-9, 0.0, None, None),
    ("robot.kp", 1e-9, 0.0, None, None),  # servo gains, friction: positive
    ("robot.friction", 1e-9, 0.0, None, None),
    ("controller.Fcx", 0.0, -0.5, None, None),  # force thresholds (N): zero allowed
    ("controller.Fcy", 0.0, -0.5, None, None),
    ("controller.Fcz", 0.0, -0.5, None, None),
    ("controller.clearance_elevator", 1e-9, 0.0, None, None),  # a clearance above the obstacle: positive
    ("controller.gait", 1, 0, 3, 4),  # 1 tripod, 2 tetrapod, 3 wave (Yu Y16)
    ("controller.setting", 1, 0, 3, 4),  # Fukuhara's three speed settings
    ("controller.case", 0, -1, 2, 3),  # 0 none, 1 L2+R2, 2 L1+R1
    ("controller.transient", 0.0, -0.5, None, None),
    ("terrain.friction", 1e-9, 0.0, None, None),
    ("terrain.jitter_m", 0.0, -0.5, None, None),
    ("criteria.fall_tilt_deg", 1e-9, 0.0, 180.0, 180.5),  # a tilt between two axes lies in [0, 180] deg
    ("criteria.max_tilt_deg", 1e-9, 0.0, 180.0, 180.5),
    ("criteria.stall_window_s", 1e-9, 0.0, None, None),  # a window has a length
    ("criteria.stall_progress_m", 0.0, -0.5, None, None),
    ("criteria.min_distance_m", 0.0, -0.5, None, None),
    ("criteria.cross_margin_m", 0.0, -0.5, None, None),
    ("criteria.end_window_s", 1e-9, 0.0, None, None),
    ("criteria.end_backslide_m", 0.0, -0.5, None, None),
    ("criteria.end_tilt_deg", 0.0, -0.5, None, None),
]


def _with(key: str, value) -> str:
    section, _, k = key.rpartition(".")
    text = 'name = "t"\n' if key == "t_end" else BASE
    return f"{text}[{section}]\n{k} = {value!r}\n" if section else f"{text}{k} = {value!r}\n"


@pytest.mark.parametrize("key, lo, below, hi, above", RANGES)
def test_every_bounded_key_accepts_its_edges_and_refuses_past_them(key, lo, below, hi, above):
    def get(s):
        node = s.doc
        for p in key.split("."):
            node = node[p]
        return node

    assert get(_doc(_with(key, lo))) == lo
    with pytest.raises(ScenarioError, match=re.escape(f"{key} = {below}") + " is out of range"):
        _doc(_with(key, below))
    if hi is not None:
        assert get(_doc(_with(key, hi))) == hi
        with pytest.raises(ScenarioError, match=re.escape(f"{key} = {above}") + " is out of range"):
            _doc(_with(key, above))


def test_the_documented_defaults_are_filled_in():
    """docs/scenarios.md, 'The document' (defaults shown)."""
    d = _doc(BASE).doc
    assert d["seed"] == 0 and d["description"] == "" and d["paper"] == "" and d["aliases"] == {}
    assert d["disturbance"] == []
    assert d["robot"] == {"preset": "yu-sim", "engine": "dart", "native": True}
    assert d["controller"] == {"kind": "yu", "params": {}}
    assert d["terrain"] == {"friction": 1.0, "jitter_m": 0.0}
    assert d["criteria"] == {"no_fall": True, "fall_tilt_deg": 45.0, "max_tilt_deg": 30.0, "no_stall": True,
                             "stall_window_s": 5.0, "stall_progress_m": 0.01, "min_distance_m": 0.0,
                             "expected_gait": "", "cross": "", "cross_margin_m": 0.25, "end_window_s": 5.0,
                             "end_backslide_m": 0.03, "end_tilt_deg": 15.0, "end_support": True}


def test_defaults_are_copies_not_shared_between_scenarios():
    a, b = _doc(BASE), _doc(BASE)
    a.doc["aliases"]["x"] = "t_end"
    a.doc["disturbance"].append({})
    a.doc["controller"]["params"]["p"] = 1.0
    assert b.doc["aliases"] == {} and b.doc["disturbance"] == [] and b.doc["controller"]["params"] == {}
    assert SCHEMA["aliases"].default == {} and SCHEMA["controller"]["params"].default == {}


def test_given_values_are_kept_and_converted():
    s = _doc(BASE + 'seed = 7.0\n[robot]\npreset = "yu-prototype"\nkp = 150\n[criteria]\nno_fall = false\n')
    assert s.doc["seed"] == 7 and type(s.doc["seed"]) is int and s.doc["robot"]["preset"] == "yu-prototype"
    assert s.doc["robot"]["kp"] == 150.0 and type(s.doc["robot"]["kp"]) is float
    assert s.doc["criteria"]["no_fall"] is False and s.doc["criteria"]["max_tilt_deg"] == 30.0
    assert s.name == "t" and s["t_end"] == 2.0


# -- validate: structure -------------------------------------------------------------------------------------

def test_unknown_keys_are_named_with_file_line_and_a_suggestion():
    msg = _err(BASE + "seeed = 1\n")
    assert msg.startswith("unknown key 'seeed' (s.toml, line 3): known keys are name, description, paper,")
    assert msg.endswith("did you mean 'seed'?")
    msg = _err(BASE + "[robot]\nbody_mas = 2.0\n")
    assert msg.startswith("unknown key 'robot.body_mas' (s.toml, line 4): known keys of [robot] are preset,")
    assert "did you mean 'body_mass'?" in msg and "feature table" not in msg
    msg = _err(BASE + "[terrain]\nfricton = 1.0\n")
    assert "known keys of [terrain] are friction, jitter_m, or a feature table [terrain.NAME]" in msg


def test_sections_and_parameter_tables_must_be_tables():
    assert _err(BASE + "robot = 3\n") == "robot must be a table (s.toml, line 3)"
    assert _err(BASE + "[controller]\nparams = 3\n") == "controller.params must be a table (s.toml, line 4)"


def test_name_is_required_and_t_end_unless_fukuhara():
    """docs/scenarios.md: name required; t_end required (Fukuhara gaits: by speed setting if absent)."""
    assert _err("t_end = 1.0\n") == "missing key 'name' (s.toml)"
    assert _err('name = "t"\n') == "missing key 't_end' (s.toml)"
    s = _doc('name = "t"\n[controller]\nkind = "fukuhara"\n')
    assert "t_end" not in s.doc
    assert _err('name = "t"\n[controller]\nkind = "yu-open-loop"\n') == "missing key 't_end' (s.toml)"


@pytest.mark.parametrize("name, ok", [
    ("step", True), ("a.b_c-1", True), ("_x", True), ("9", True), ("x" * 100, True),
    ("x" * 101, False), ("a/b", False), (".", False), ("..", False), (".hidden", False), ("-x", False),
    ("", False), ("a b", False),
])
def test_the_name_is_a_plain_folder_name(name, ok):
    """The default output folder is runs/<name>: letters, digits, '.', '_', '-', at most 100 characters, not
    starting with '.' or '-' (no hidden folders or options), never '.' or '..'."""
    text = f"name = {name!r}\nt_end = 1.0\n".replace("'", '"')
    if ok:
        assert _doc(text).name == name
    else:
        assert _err(text).startswith(f"name = {name!r} must be a plain name")


def test_aliases_name_string_keys_and_params_are_finite_numbers():
    assert _err(BASE + "[aliases]\nh = 3\n") == "aliases.h must be a string key, got int 3 (s.toml, line 4)"
    _doc(BASE + '[aliases]\nh = "terrain.step.height"\n')
    for bad, shown in (("true", "bool True"), ('"x"', "'x'"), ("nan", "float nan"), ("inf", "float inf")):
        msg = _err(BASE + f'[controller.params]\neps = {bad}\n')
        assert msg == f"controller parameter eps must be a finite number, got {shown} (s.toml, line 4)"
    s = _doc(BASE + '[controller.params]\n"*.eps" = 1\n"a.b" = -0.5\n')
    assert s.doc["controller"]["params"] == {"*.eps": 1, "a.b": -0.5}


def test_features_need_a_known_type_and_valid_fields():
    step = '[terrain.s]\ntype = "step"\nheight = 0.04\nposition_y = 0.5\nside = "right"\n'
    s = _doc(BASE + step)
    assert s.features() == {"s": {"type": "step", "height": 0.04, "position_y": 0.5, "side": "right"}}
    msg = _err(BASE + step.replace('"step"', '"stepp"'))
    assert msg.startswith("terrain.s.type must be one of step, ditch, gap,") and "did you mean 'step'?" in msg
    assert msg.endswith("(s.toml, line 4)")
    msg = _err(BASE + step.replace('type = "step"\n', ""))  # in a file (not --set): a missing type
    assert msg.startswith("terrain.s.type must be one of") and "got NoneType None" in msg
    msg = _err(BASE + step.replace("height = 0.04", "height = -0.04"))
    assert "terrain.s.height" in msg and msg.endswith("(s.toml, line 5)")


def test_cross_must_name_a_feature():
    assert _err(BASE + '[criteria]\ncross = "step"\n') == \
        "criteria.cross = 'step' names no terrain feature (features: none) (s.toml, line 4)"
    step = '[terrain.s]\ntype = "step"\nheight = 0.04\nposition_y = 0.5\nside = "right"\n'
    assert "(features: s)" in _err(BASE + '[criteria]\ncross = "x"\n' + step)
    assert _doc(BASE + '[criteria]\ncross = "s"\n' + step).doc["criteria"]["cross"] == "s"


def test_disturbances_are_checked():
    ok = BASE + "[[disturbance]]\nstart_s = 1.0\nduration_s = 0.5\nforce_N = [0.0, 1.0, 0.0]\n"
    assert _doc(ok).doc["disturbance"] == [{"start_s": 1.0, "duration_s": 0.5, "force_N": [0.0, 1.0, 0.0]}]
    msg = _err(ok.replace("duration_s = 0.5", "duration_s = 0.0"))
    assert "disturbance[0].duration_s" in msg and msg.endswith("(s.toml, line 3)")


# -- where: file and line, or --set --------------------------------------------------------------------------

def test_line_of_follows_tables_dotted_and_quoted_keys():
    text = ('name = "x"  # comment = 1\n'
            "[robot]\n"
            "kp = 1.0\n"
            "[ controller.params ]\n"
            '"eps" = 2\n'
            "[[disturbance]]\n"
            "start_s = 1\n"
            'terrain.step.height = 0.1\n'
            "# t_end = 3\n")
    assert line_of(text, "name") == 1 and line_of(text, "robot") == 2 and line_of(text, "robot.kp") == 3
    assert line_of(text, "controller.params") == 4 and line_of(text, "controller.params.eps") == 5
    assert line_of(text, "disturbance") == 6 and line_of(text, "disturbance.start_s") == 7
    assert line_of(text, "disturbance.terrain.step.height") == 8
    assert line_of(text, "kp") is None and line_of(text, "t_end") is None and line_of(text, "comment") is None


def test_a_quoted_key_with_dots_is_found():
    """TOML (toml.io v1.0.0, Keys): "*.a.b" in quotes is one key, so the parameter controller.params."*.a.b" is
    written on line 2 of this text."""
    assert line_of('[controller.params]\n"*.a.b" = 2\n', 'controller.params."*.a.b"') == 2
    assert line_of('[controller.params]\n"*.a.b" = 2\n', "controller.params.*.a.b") == 2


def test_an_error_without_a_line_names_the_file_only():
    s = Scenario({"name": "t", "t_end": -1.0}, "built-in X", "")
    with pytest.raises(ScenarioError, match=re.escape("t_end = -1.0 is out of range: must be > 0 (built-in X)")):
        validate(s)


# -- --set ---------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("text, value", [
    ("0.06", 0.06), (" 3 ", 3), ("true", True), ("false", False), ("[1, 2]", [1, 2]), ('"two words"', "two words"),
    ("left", "left"), ("a-b+c", "a-b+c"), ("_x1", "_x1"), ("1e3", 1000.0),
])
def test_set_values_are_toml_or_a_bare_word(text, value):
    got = parse_value(text)
    assert got == value and type(got) is type(value)


@pytest.mark.parametrize("text", ["two words", "1x", "-x", "[1,", "a=b", ""])
def test_other_set_values_are_refused(text):
    with pytest.raises(ScenarioError, match=re.escape(f"value {text.strip()!r} is not a TOML value")):
        parse_value(text)


def test_set_keys_resolve_to_document_paths():
    """docs/scenarios.md, Overrides: dotted paths; controller paths outside the schema are graph
    parameters; a key without a dot is an alias, a top-level key, else under controller."""
    s = _doc(BASE + '[aliases]\nh = "terrain.step.height"\n')
    assert resolve_key(s, "h") == ["terrain", "step", "height"]
    assert resolve_key(s, " t_end ") == ["t_end"] and resolve_key(s, "seed") == ["seed"]
    assert resolve_key(s, "Fcx") == ["controller", "Fcx"] and resolve_key(s, "rule2") == ["controller", "params",
                                                                                            "rule2"]
    assert resolve_key(s, "robot") == ["controller", "params", "robot"]  # a section is no scalar key
    assert resolve_key(s, "controller.Fcx") == ["controller", "Fcx"]
    assert resolve_key(s, "controller.R1.reflex.x1_apex") == ["controller", "params", "R1.reflex.x1_apex"]
    assert resolve_key(s, "robot.body_mass") == ["robot", "body_mass"]
    assert resolve_key(s, "terrain.step.height") == ["terrain", "step", "height"]
    with pytest.raises(ScenarioError, match="terrain keys are terrain.KEY or terrain.FEATURE.FIELD"):
        resolve_key(s, "terrain.step.height.x")
    with pytest.raises(ScenarioError, match="empty --set key"):
        resolve_key(s, "  ")


def test_overrides_create_tables_and_refuse_unknown_paths():
    s = _doc(BASE)
    apply_override(s, "terrain.new.type", "gap")
    assert s.doc["terrain"]["new"] == {"type": "gap"}
    apply_override(s, "h2", 1.5)  # -> controller.params.h2
    assert s.doc["controller"]["params"]["h2"] == 1.5
    assert s.overrides == {"terrain.new.type": "gap", "controller.params.h2": 1.5, "h2": 1.5}
    s.doc.pop("robot")
    apply_override(s, "robot.kp", 3.0)  # a section the document lacks is created
    assert s.doc["robot"] == {"kp": 3.0}
    with pytest.raises(ScenarioError, match=re.escape("--set t_end.x: t_end is not a table")):
        apply_override(s, "t_end.x", 1)
    with pytest.raises(ScenarioError, match=re.escape("--set nme.x: unknown key 'nme.x'; did you mean 'name'?")):
        apply_override(s, "nme.x", 1)


def test_a_long_unknown_key_is_unknown_not_a_terrain_key():
    """The terrain rule (terrain.KEY or terrain.FEATURE.FIELD, docs/scenarios.md) is about keys under
    terrain only: a four-part key under a top-level name that does not exist, here one that sorts after
    "terrain", is an unknown key like any other, not a malformed terrain key."""
    s = _doc(BASE)
    with pytest.raises(ScenarioError, match=re.escape("--set zone.a.b.c: unknown key 'zone.a.b.c'")):
        apply_override(s, "zone.a.b.c", 1)
    with pytest.raises(ScenarioError, match=re.escape("--set terrain.a.b.c: terrain keys are terrain.KEY or")):
        apply_override(s, "terrain.a.b.c", 1)


def test_overridden_errors_say_set_and_the_feature_rules():
    with pytest.raises(ScenarioError, match=re.escape("t_end = -1.0 is out of range: must be > 0 (--set t_end, ")):
        load("flat", {"t_end": -1.0})
    with pytest.raises(ScenarioError, match=re.escape("terrain.q is not a terrain feature of this scenario")):
        load("flat", {"terrain.q.height": 0.1})
    with pytest.raises(ScenarioError, match=re.escape("(features: none; to add one, also set terrain.q.type")):
        load("flat", {"terrain.q.height": 0.1})
    assert load("flat", {"t_end": 3}).doc["t_end"] == 3.0  # validated again: the int becomes a float


# -- loading -------------------------------------------------------------------------------------------------

def test_files_and_built_in_names(tmp_path):
    p = tmp_path / "mine.toml"
    p.write_text(BASE)
    s = load(p)
    assert s.source == str(p) and s.doc["t_end"] == 2.0 and s.text == BASE
    p.write_text("name = \n")
    with pytest.raises(ScenarioError, match=re.escape(f"{p}: not valid TOML")):
        load(p)
    with pytest.raises(ScenarioError, match=re.escape(f"scenario file {tmp_path / 'no.toml'} does not exist")):
        load(tmp_path / "no.toml")
    with pytest.raises(ScenarioError, match=re.escape("unknown scenario 'nosuch' (built-in: ditches, flat,")):
        load("nosuch")
    for spec in ("dir/flat", "flat.txt"):  # a path (a slash or a suffix) is a file, never a built-in name
        with pytest.raises(ScenarioError, match="does not exist"):
            load(spec)
    flat = load("flat")
    assert flat.source == "built-in scenario flat"  # the package's own file: no path a user would look for
    assert sc.builtin_descriptions()["flat"] == flat.doc["description"]


# -- writing (what --show prints) ----------------------------------------------------------------------------

def test_toml_values_by_hand():
    doc = {"name": "a\"b\\c", "b": True, "c": False, "n": 3, "x": 0.5, "l": [1, "q"],
           "controller": {"params": {"*.eps": 0.25}, "kind": "yu"}, "empty": {},
           "disturbance": [{"start_s": 1.0, "force_N": [0.0]}]}
    text = dump_toml(doc)
    assert text == ('name = "a\\"b\\\\c"\nb = true\nc = false\nn = 3\nx = 0.5\nl = [1, "q"]\n'
                    'disturbance = [{start_s = 1.0, force_N = [0.0]}]\n\n[controller]\nkind = "yu"\n\n'
                    '[controller.params]\n"*.eps" = 0.25\n\n[empty]\n')
    assert tomllib.loads(text) == doc
    # a table holding only tables writes no header of its own (TOML: [a.b] defines a)
    assert dump_toml({"a": {"b": {"c": 1}}}) == "[a.b]\nc = 1\n"
    with pytest.raises(ScenarioError, match="cannot write None as TOML"):
        dump_toml({"x": None})


def test_a_file_that_is_not_utf8_is_a_scenario_error(tmp_path):
    """TOML files are UTF-8 (toml.io v1.0.0, Spec): other bytes are refused with the file's name."""
    p = tmp_path / "latin.toml"
    p.write_bytes(b'name = "caf\xe9"\nt_end = 1.0\n')
    with pytest.raises(ScenarioError, match=re.escape(f"cannot read scenario file {p}:")):
        load(p)


def test_keys_after_a_parameter_table_are_still_checked():
    """[controller] with its params table written first (an inline table), then a key out of range."""
    msg = _err(BASE + "[controller]\nparams = {a = 1}\nFcx = -1.0\n")
    assert msg.startswith("controller.Fcx = -1.0 is out of range: must be >= 0")
    s = _doc(BASE + '[controller]\nparams = {a = 1}\nkind = "yu"\n')
    assert s.doc["criteria"]["max_tilt_deg"] == 30.0


def test_only_controller_paths_become_graph_parameters():
    """Keys of other sections, including those that sort before 'controller', stay where they are."""
    s = _doc(BASE)
    assert resolve_key(s, "aliases.h") == ["aliases", "h"]
    assert resolve_key(s, "criteria.cross") == ["criteria", "cross"]
    assert resolve_key(s, "disturbance") == ["disturbance"]


def test_a_table_header_with_a_comment_is_followed():
    assert line_of("[robot]  # the robot\nkp = 1.0  # N*m/rad\n", "robot.kp") == 2


def test_terrain_keys_after_an_inline_feature_are_still_checked():
    feat = 's = {type = "step", height = 0.04, position_y = 0.5, side = "right"}'
    msg = _err(BASE + f"[terrain]\n{feat}\njitter_m = -1.0\n")
    assert msg.startswith("terrain.jitter_m = -1.0 is out of range: must be >= 0")


def test_long_paths_outside_terrain_are_not_terrain_errors():
    """The 'terrain.KEY or terrain.FEATURE.FIELD' rule is about terrain keys only."""
    s = _doc(BASE)
    assert resolve_key(s, "criteria.a.b.c") == ["criteria", "a", "b", "c"]


def test_a_sub_table_in_a_section_other_than_terrain_is_an_unknown_key():
    """Only [terrain] holds named tables (features); [robot.sub] is no key of [robot]."""
    assert _err(BASE + "[robot.sub]\na = 1\n").startswith("unknown key 'robot.sub'")


def test_overrides_make_missing_tables_only_inside_sections():
    s = _doc(BASE)
    assert resolve_key(s, "terrain.friction") == ["terrain", "friction"]
    apply_override(s, "robot.sub.x", 1)  # a table inside a section is made (validation judges it after)
    assert s.doc["robot"]["sub"] == {"x": 1}
    for key in ("nme.x.y", "zzz.x.y", "abc.x.y"):  # no such section: nothing is made
        with pytest.raises(ScenarioError, match=re.escape(f"--set {key}: unknown key '{key}'")):
            apply_override(s, key, 1)
