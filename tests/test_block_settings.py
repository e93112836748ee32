"""Every algorithm's settings block reads a dict, keeps a block it is given, is frozen, and
refuses a non-mapping in one line naming the block."""

from __future__ import annotations

import pytest

from rllib_asor.algorithms.bco.settings import BcoSettings
from rllib_asor.algorithms.cadm.settings import CadmSettings
from rllib_asor.algorithms.escp.settings import EscpSettings
from rllib_asor.algorithms.gaifo.settings import GaifoSettings
from rllib_asor.algorithms.garat.settings import GaratSettings
from rllib_asor.algorithms.osi.settings import OsiSettings
from rllib_asor.algorithms.soil.settings import SoilSettings
from rllib_asor.settings_model import BlockSettings

BLOCKS = [
    BcoSettings, CadmSettings, EscpSettings, GaifoSettings, GaratSettings, OsiSettings, SoilSettings
]
NAMES = {
    "bco": "BCO", "cadm": "CaDM", "escp": "ESCP", "gaifo": "GAIfO", "garat": "GARAT", "osi": "OSI",
    "soil": "SOIL",
}


def test_every_block_is_listed():
    listed = {cls.block for cls in BLOCKS}
    found = {cls.block for cls in BlockSettings.__subclasses__()}
    assert found == listed, found ^ listed


@pytest.mark.parametrize("cls", BLOCKS, ids=lambda c: c.block)
def test_none_gives_the_defaults_and_a_block_is_kept(cls):
    defaults = cls.from_dict(None)
    assert defaults == cls()
    assert cls.from_dict(defaults) is defaults
    assert cls.from_dict(defaults.to_dict()) == defaults


@pytest.mark.parametrize("cls", BLOCKS, ids=lambda c: c.block)
@pytest.mark.parametrize("value", [3, [1, 2], "fast"])
def test_a_non_mapping_is_refused_in_one_line(cls, value):
    name = NAMES[cls.block]
    expected = f"{cls.block}={value!r} is not allowed; expected a mapping of {name} settings"
    with pytest.raises(ValueError) as error:
        cls.from_dict(value)
    assert str(error.value) == expected


@pytest.mark.parametrize("cls", BLOCKS, ids=lambda c: c.block)
def test_a_block_is_frozen(cls):
    block = cls()
    key = next(iter(cls.model_fields))
    with pytest.raises(ValueError, match="frozen"):
        setattr(block, key, getattr(block, key))


@pytest.mark.parametrize("cls", BLOCKS, ids=lambda c: c.block)
def test_an_unknown_key_names_the_block(cls):
    with pytest.raises(ValueError, match=rf"^{cls.block}\.not_a_key is not an? \S+ setting"):
        cls.from_dict({"not_a_key": 1})
