"""Figure helpers: the contact maps' scale bar picks a round length near a quarter of the map."""

import pytest

from thirdbody.plot import _nice_length


@pytest.mark.parametrize("span, expected", [(130.0, 20.0), (400.0, 100.0), (90.0, 20.0),
                                            (2.4, 0.5), (5000.0, 1000.0)])
def test_scale_bar_length_is_round_and_at_most_a_quarter(span, expected):
    length = _nice_length(span)
    assert length == pytest.approx(expected)
    assert length <= span / 4 < 2.5 * length
