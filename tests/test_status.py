"""The optimisers' outcome codes: items of an `eqx.Enumeration`, held as integer codes by
the results and read back as messages."""

import equinox as eqx
import numpy as np
import pytest

from tid_jax._outcomes import outcome_code, outcome_message
from tid_jax._retune import RetuneOutcome
from tid_jax._robust import RobustOutcome


class _Outcome(eqx.Enumeration):
    ok = "ok"
    failed = "it failed"


def test_codes_follow_the_order_given_and_explain_themselves():
    assert (outcome_code(_Outcome.ok), outcome_code(_Outcome.failed)) == (0, 1)
    assert outcome_message(_Outcome, np.asarray(1)) == "it failed" == _Outcome[_Outcome.failed]
    assert outcome_message(_Outcome, 0) == "ok"
    with pytest.raises(AttributeError):
        _Outcome.missing  # noqa: B018


@pytest.mark.parametrize("outcomes", [RetuneOutcome, RobustOutcome])
def test_success_is_code_0_and_every_message_differs(outcomes):
    messages = [outcome_message(outcomes, code) for code in range(len(outcomes))]
    assert outcome_code(outcomes.ok) == 0 and messages[0] == "ok"
    assert len(set(messages)) == len(messages)


def test_the_codes_results_hold_are_those_of_their_items():
    assert outcome_code(RetuneOutcome.initial_kept) == 4
    assert outcome_code(RetuneOutcome.stuck) == 5
    assert outcome_code(RobustOutcome.stroke_over_limit) == 3
    assert "initial tuning kept" in outcome_message(RetuneOutcome, 4)
    assert outcome_message(RobustOutcome, 3) == "stroke over the limit on the check grid"
