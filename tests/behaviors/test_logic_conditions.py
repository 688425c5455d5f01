import pytest
from hypothesis import given, settings, strategies as st

from behaviors.logic import (ConditionError, Junction, Not, Relation, field_match, parse_behavior_condition,
                             parse_condition, parse_mode_condition)


def lookup(values):
    return values.get


def test_relation_parse_types():
    assert parse_condition("DEPLOY = true") == Relation("DEPLOY", "=", "true")
    assert parse_condition("SPEED >= 2.5") == Relation("SPEED", ">=", 2.5)
    assert parse_condition('X = "12"') == Relation("X", "=", "12")
    assert parse_condition("A != $(B)") == Relation("A", "!=", other_var="B")
    assert parse_condition("MODE==LOITERING") == Relation("MODE", "==", "LOITERING")


def test_unknown_variable_is_false_even_for_not_equal():
    cond = parse_condition("RETURN != true")
    assert cond.evaluate(lookup({})) is False
    assert cond.evaluate(lookup({"RETURN": "false"})) is True


def test_string_and_number_comparisons():
    v = {"S": "12", "T": "abc", "D": 3.0}
    assert parse_condition("S > 5").evaluate(lookup(v))
    assert not parse_condition("T > 5").evaluate(lookup(v))
    assert parse_condition("D = 3").evaluate(lookup(v))
    assert parse_condition("D == 3").evaluate(lookup(v))
    assert not parse_condition("T = ABC").evaluate(lookup(v))  # case-sensitive


def test_field_match_rules_and_three_field_quirk():
    assert field_match("ACTIVE:SURVEYING", "SURVEYING")
    assert field_match("ACTIVE", "ACTIVE:SURVEYING")
    assert not field_match("ACTIVE:SURVEYING", "VEY")
    assert field_match("ACTIVE:SURVEYING", "ACTIVE:SURVEYING")
    assert not field_match("A:B:C", "A:B:C")
    assert parse_condition("MODE == SURVEYING").evaluate(lookup({"MODE": "ACTIVE:SURVEYING"}))


def test_and_or_not_need_parentheses():
    cond = parse_condition("(A=1) and ((B<2) or !(C=x))")
    assert isinstance(cond, Junction) and isinstance(cond.right, Junction)
    assert isinstance(cond.right.right, Not)
    assert cond.evaluate(lookup({"A": 1.0, "B": 5.0, "C": "y"}))
    assert not cond.evaluate(lookup({"A": 1.0, "B": 5.0, "C": "x"}))
    with pytest.raises(ConditionError):
        parse_condition("A=1 and B=2")
    with pytest.raises(ConditionError):
        parse_condition("(A=1) and (B<2) and (C!=4)")


def test_behavior_commas_and_mode_ban():
    assert parse_behavior_condition("DEPLOY,true") == Relation("DEPLOY", "=", "true")
    with pytest.raises(ConditionError):
        parse_mode_condition("MODE == X")
    assert parse_mode_condition("(MODE == X) and (Y = 1)")
    with pytest.raises(ConditionError):
        parse_condition("= 4")


@settings(max_examples=60, deadline=None)
@given(st.floats(-1e6, 1e6, allow_nan=False), st.floats(-1e6, 1e6, allow_nan=False),
       st.sampled_from(["<", ">", "<=", ">=", "=", "!="]))
def test_numeric_relations_match_python(a, b, op):
    import operator
    ops = {"<": operator.lt, ">": operator.gt, "<=": operator.le, ">=": operator.ge, "=": operator.eq,
           "!=": operator.ne}
    cond = parse_condition(f"X {op} {b!r}")
    assert cond.evaluate(lookup({"X": a})) == ops[op](a, float(repr(b)))


_names = st.sampled_from(["DEPLOY", "MODE", "NAV_X", "RETURN_ALL", "X1"])
_relations = st.builds(Relation, _names, st.sampled_from(["=", "==", "!=", "<", "<=", ">", ">="]),
                       st.one_of(st.integers(-99, 99).map(float), st.sampled_from(["true", "ACTIVE:SURVEY", "x_y"])))
_conditions = st.recursive(_relations, lambda inner: st.one_of(
    st.builds(Not, inner), st.builds(Junction, st.sampled_from(["and", "or"]), inner, inner)), max_leaves=6)


@settings(max_examples=60, deadline=None)
@given(_conditions)
def test_printed_condition_parses_back(cond):
    assert parse_condition(str(cond)) == cond
