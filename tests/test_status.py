"""The shared outcome codes of the optimisers."""

import numpy as np
import pytest

from tid_jax._retune import RETUNE_OUTCOMES
from tid_jax._robust import ROBUST_OUTCOMES
from tid_jax._status import Outcomes


def test_codes_follow_the_order_given_and_explain_themselves():
    outcomes = Outcomes(ok="ok", failed="it failed")
    assert (outcomes.ok, outcomes.failed) == (0, 1)
    assert outcomes.message(np.asarray(1)) == "it failed"
    assert outcomes.messages() == {0: "ok", 1: "it failed"}
    with pytest.raises(AttributeError, match="no outcome 'missing'"):
        outcomes.missing  # noqa: B018


@pytest.mark.parametrize("outcomes", [RETUNE_OUTCOMES, ROBUST_OUTCOMES])
def test_success_is_code_0_and_every_message_differs(outcomes):
    messages = outcomes.messages()
    assert outcomes.ok == 0 and messages[0] == "ok"
    assert len(set(messages.values())) == len(messages)
