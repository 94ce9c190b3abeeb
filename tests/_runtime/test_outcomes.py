"""The outcome codes: items of one `eqx.Enumeration`, `Outcome`, held as integer codes by
every result and read back as messages."""

import equinox as eqx
import numpy as np
import pytest

from tid_jax._runtime._outcomes import Outcome, outcome_code, outcome_message, outcome_messages


class _Outcome(eqx.Enumeration):
    ok = "ok"
    failed = "it failed"


def test_codes_follow_the_order_given_and_explain_themselves():
    assert (outcome_code(_Outcome.ok), outcome_code(_Outcome.failed)) == (0, 1)
    assert outcome_message(_Outcome, np.asarray(1)) == "it failed" == _Outcome[_Outcome.failed]
    assert outcome_message(_Outcome, 0) == "ok"
    with pytest.raises(AttributeError):
        _Outcome.missing  # noqa: B018


def test_success_is_code_0_and_every_message_differs():
    messages = [outcome_message(Outcome, code) for code in range(len(Outcome))]
    assert outcome_code(Outcome.ok) == 0 and messages[0] == "ok"
    assert len(set(messages)) == len(messages)


def test_the_codes_results_hold_are_those_of_their_items():
    assert outcome_code(Outcome.initial_kept) == 4
    assert outcome_code(Outcome.stuck) == 5
    assert outcome_code(Outcome.stroke_over_limit) == 6
    assert "initial tuning kept" in outcome_message(Outcome, 4)
    assert outcome_message(Outcome, 6) == "stroke over the limit on the check grid"


def test_every_result_s_messages_are_those_of_its_codes_in_order():
    assert outcome_messages(np.asarray(6)) == [outcome_message(Outcome, 6)]
    assert outcome_messages(np.asarray([[0, 3], [1, 0]])) == [
        "ok", outcome_message(Outcome, 3), outcome_message(Outcome, 1), "ok"]
