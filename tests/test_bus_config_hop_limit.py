"""udp_multicast's hop_limit is checked where the bus configuration is made: a text or a value that
does not fit the IP header's one byte is one line, exit 2 (it was python-can's struct.error traceback,
exit 1, from `--bus-option hop_limit=abc`)."""

from __future__ import annotations

import pytest

from drives.bus_config import LOCAL_HOP_LIMIT, resolve_bus_config
from drives.errors import ParameterError

GROUP = {"interface": "udp_multicast", "channel": "239.74.163.2", "port": 43113}


def test_no_hop_limit_stays_on_this_host() -> None:
    assert resolve_bus_config(**GROUP)["hop_limit"] == LOCAL_HOP_LIMIT


def test_a_hop_limit_the_user_names_is_kept() -> None:
    assert resolve_bus_config(**GROUP, hop_limit=1)["hop_limit"] == 1


@pytest.mark.parametrize("hops", ["abc", -1, 256, 1.5, True])
def test_a_hop_limit_that_is_no_byte_is_refused_in_one_line(hops: object) -> None:
    with pytest.raises(ParameterError) as refused:
        resolve_bus_config(**GROUP, hop_limit=hops)
    assert "hop_limit" in str(refused.value) and "0..255" in str(refused.value)
    assert "\n" not in str(refused.value)
