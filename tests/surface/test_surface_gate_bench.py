"""`bench/surface_gate.py` reads its variants as NAME=GATE_M,ROUNDS and refuses malformed ones naming them."""

import pytest

from bench.surface_gate import DEFAULT_VARIANTS, parse_variant


def test_variants_parse_and_the_defaults_start_with_the_old_gate():
    assert parse_variant("gate 1 m, 4 rounds=1.0,4") == ("gate 1 m, 4 rounds", 1.0, 4)
    assert parse_variant("a=b=0.5,1") == ("a=b", 0.5, 1)  # the name may hold '='
    assert [parse_variant(text)[1:] for text in DEFAULT_VARIANTS][0] == (0.1, 1)


@pytest.mark.parametrize("text", ["wide", "wide=0.5", "wide=0.5,x", "=0.5,4", "wide=0,4", "wide=0.5,0"])
def test_a_malformed_variant_is_refused_naming_it(text: str):
    with pytest.raises(SystemExit, match="--variant"):
        parse_variant(text)
