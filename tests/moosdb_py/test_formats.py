"""moosdb_py.formats: one meaning per MOOS text format, and round trips for every writer."""
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from moosdb_py.formats import (FormatError, format_bool, format_fixed, format_number, format_pairs,
                               format_points, format_seglist, parse_bool, parse_number, parse_pairs,
                               parse_seglist, split_fields, split_quoted, wild_match)

finite = st.floats(allow_nan=False, allow_infinity=False, min_value=-1e9, max_value=1e9)


@pytest.mark.parametrize("text, value", [("true", True), ("TRUE", True), ("On", True), ("1", True), ("0.5", True),
                                         ("false", False), ("OFF", False), ("0", False), ("-1", False),
                                         (" true ", True)])
def test_bool_agrees_with_moos_core_and_ivp_where_both_answer(text, value):
    assert parse_bool(text) is value


@pytest.mark.parametrize("text", ["yes", "no", "", "tru", "1x", "nan"])
def test_bool_rejects_what_is_not_a_moos_boolean(text):
    with pytest.raises(FormatError, match="expected true or false"):
        parse_bool(text)


@given(st.booleans())
def test_bool_round_trip(value):
    assert parse_bool(format_bool(value)) is value


@pytest.mark.parametrize("value, digits, text", [(1.0, 3, "1"), (1.5, 3, "1.5"), (-0.0001, 3, "0"), (2.0004, 3, "2"),
                                                 (12.34567, 2, "12.35"), (100.0, 0, "100"), (-3.25, 5, "-3.25"),
                                                 (1e6, 5, "1000000")])
def test_number_printing_is_doubletostringx(value, digits, text):
    assert format_number(value, digits) == text


def test_fixed_keeps_the_decimals():
    assert format_fixed(1, 1) == "1.0" and format_fixed(-2.25, 3) == "-2.250"


@given(finite, st.integers(0, 9))
def test_number_round_trip_within_the_printed_precision(value, digits):
    text = format_number(value, digits)
    assert abs(parse_number(text) - value) <= 0.5 * 10 ** -digits * (1 + 1e-9) + abs(value) * 1e-15
    assert text != "-0" and not (("." in text) and text.endswith(("0", ".")))


@pytest.mark.parametrize("text", ["", "abc", "1_000", "nan", "inf", "-inf", "1e999", "1,5", "0x10"])
def test_number_rejects_what_atof_would_not_read_whole(text):
    with pytest.raises(FormatError):
        parse_number(text)


@pytest.mark.parametrize("text, value", [("1", 1.0), (" -2.5 ", -2.5), (".5", 0.5), ("3.", 3.0), ("1e3", 1000.0),
                                         ("+4", 4.0)])
def test_number_parses_moos_numbers(text, value):
    assert parse_number(text) == value


def test_pairs_split_outside_braces_lower_case_keys_last_wins():
    assert parse_pairs("A=1, b = x ,,pts={1,2:3,4},a=2") == {"a": "2", "b": "x", "pts": "{1,2:3,4}"}
    assert parse_pairs("points=1,2:3,4#repeat=forever", sep="#") == {"points": "1,2:3,4", "repeat": "forever"}
    assert split_fields("a=1,pts={1,2},b=3") == ["a=1", "pts={1,2}", "b=3"]
    with pytest.raises(FormatError, match="'oops' is not key=value"):
        parse_pairs("a=1,oops")


keys = st.from_regex(r"[a-z][a-z_0-9]{0,8}", fullmatch=True)
values = st.from_regex(r"[A-Za-z0-9_.:\-]{0,10}", fullmatch=True)


@given(st.dictionaries(keys, values, max_size=6))
def test_pairs_round_trip(pairs):
    assert parse_pairs(format_pairs(pairs)) == pairs
    assert parse_pairs(format_pairs(pairs, sep="#"), sep="#") == pairs


def test_pairs_write_floats_as_moos_numbers():
    assert format_pairs({"x": 1.50, "name": "abe", "n": 3}) == "x=1.5,name=abe,n=3"


@pytest.mark.parametrize("text, points", [
    ("pts={1,2:3,4}", [(1, 2), (3, 4)]),
    ("pts={1,2,0:3,4,5},label=foo", [(1, 2), (3, 4)]),
    ("label=foo, pts = { 1 , 2 : 3 , 4 }", [(1, 2), (3, 4)]),
    ("1,2:3,4", [(1, 2), (3, 4)]),
    ("points: 1,2 : 3,4", [(1, 2), (3, 4)]),
    ("pts: 1,2:3,4:label,foo", [(1, 2), (3, 4)]),
    ("x=1,y=2:x=3,y=4", [(1, 2), (3, 4)]),
    ("{5,6:7,8}", [(5, 6), (7, 8)]),
])
def test_seglist_forms(text, points):
    assert parse_seglist(text) == [tuple(map(float, p)) for p in points]


@pytest.mark.parametrize("text, reason", [
    ("pts={1,2:3}", "vertex 2 '3' is not x,y"),
    ("pts={1,2,3,4:3,4}", "more than x,y,z"),
    ("pts={1,2:3,4", "unclosed"),
    ("pts={a,b:3,4}", "vertex 1 'a,b' is not x,y"),
    ("pts={1,nan:3,4}", "vertex 1 '1,nan' is not x,y"),
    ("format=lawnmower,x=0,y=0", "generated pattern"),
    ("label,foo", "no points"),
    ("60,-40 : 60,-160 : oops", "vertex 3 'oops' is not x,y"),
    ("x=1:x=2,y=3", "needs x= and y="),
])
def test_seglist_errors_name_the_vertex(text, reason):
    with pytest.raises(FormatError, match=reason):
        parse_seglist(text)


@given(st.lists(st.tuples(finite, finite), min_size=1, max_size=12), st.integers(0, 6))
def test_seglist_round_trip(points, digits):
    for text in (format_seglist(points, digits), format_points(points, digits),
                 format_seglist(points, digits, fixed=True) + ",label=x"):
        back = parse_seglist(text)
        assert len(back) == len(points)
        for (x, y), (bx, by) in zip(points, back):
            assert math.isclose(bx, x, abs_tol=0.51 * 10 ** -digits, rel_tol=1e-12)
            assert math.isclose(by, y, abs_tol=0.51 * 10 ** -digits, rel_tol=1e-12)


def test_seglist_writing_forms():
    assert format_seglist([(0, 0), (400, 0.25)], 1, fixed=True) == "pts={0.0,0.0:400.0,0.2}"
    assert format_seglist([(0, 0), (400, 0.25)]) == "pts={0,0:400,0.25}"


@pytest.mark.parametrize("pattern, text, hit", [
    ("*", "", True), ("NAV_*", "NAV_X", True), ("NAV_*", "nav_x", False), ("?AV", "NAV", True),
    ("N?V_X", "NAV_XY", False), ("a.b", "axb", False), ("[ab]", "[ab]", True), ("*_X", "NAV_X\nY", False),
])
def test_wild_match_is_mooswildcmp(pattern, text, hit):
    assert wild_match(pattern, text) is hit


@given(st.text(alphabet="ab*?.", max_size=6), st.text(alphabet="ab.", max_size=6))
def test_wild_match_agrees_with_fnmatch_on_star_and_question(pattern, text):
    import fnmatch
    assert wild_match(pattern, text) == fnmatch.fnmatchcase(text, pattern)


def test_quoted_fields_keep_their_commas():
    """MOOS's parseStringQ: commas inside double quotes do not split; `unquoted` drops the quotes."""
    assert split_fields('a=1,s="x,y",b=2') == ["a=1", 's="x,y"', "b=2"]
    assert parse_pairs('var=X, string_val="a, b=c"', unquoted=True) == {"var": "X", "string_val": "a, b=c"}
    assert split_quoted('id=avd, val="name=$[VNAME] # contact=$[VNAME]", ') == \
        ["id=avd", "val=name=$[VNAME] # contact=$[VNAME]"]
    with pytest.raises(FormatError, match="unclosed double quote"):
        split_fields('a="open,b=2')


@given(st.lists(st.sampled_from(["a", "=", "1", ",", "{", "}", " ", '"', ":"]), max_size=30).map("".join),
       st.text(alphabet="ab1,:= ", max_size=12))
def test_fields_rejoin_and_braces_or_quotes_keep_commas(text, inner):
    """Whatever the path (a plain split when nothing is quoted or braced), the fields rejoin to the
    text; a braced or quoted value is one field however many commas it holds."""
    try:
        assert ",".join(split_fields(text)) == text
    except FormatError:
        assert text.count('"') % 2 == 1
    if '"' not in text and "{" not in text:
        assert split_fields(text) == text.split(",")
    assert split_fields(f"a=1,pts={{{inner}}},s=\"{inner}\"") == ["a=1", f"pts={{{inner}}}", f's="{inner}"']
