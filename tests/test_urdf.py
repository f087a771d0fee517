"""bcad's URDF reader against yourdfpy's on the same file."""

from __future__ import annotations

import numpy as np
import pytest
import yourdfpy

from bcad.compile.urdf import read_urdf
from bcad.errors import InputError

from conftest import RX90_URDF


def test_reader_agrees_with_yourdfpy():
    ours = read_urdf(RX90_URDF)
    theirs = yourdfpy.URDF.load(str(RX90_URDF), build_scene_graph=False, load_meshes=False).robot
    assert ours.links == [link.name for link in theirs.links]
    assert len(ours.joints) == len(theirs.joints) == 6
    for mine, reference in zip(ours.joints, theirs.joints):
        assert (mine.name, mine.type, mine.parent, mine.child) == (
            reference.name, reference.type, reference.parent, reference.child,
        )
        np.testing.assert_allclose(mine.origin, reference.origin, atol=1e-15)
        np.testing.assert_allclose(mine.axis, reference.axis)
        assert (mine.lower, mine.upper) == (reference.limit.lower, reference.limit.upper)


def test_rx90_limits_are_the_published_ones():
    degrees = {j.name: (np.degrees(j.lower), np.degrees(j.upper)) for j in read_urdf(RX90_URDF).joints}
    expected = {
        "joint_1": (-160, 160), "joint_2": (-137.5, 137.5), "joint_3": (-142.5, 142.5),
        "joint_4": (-270, 270), "joint_5": (-105, 120), "joint_6": (-270, 270),
    }
    for name, (low, high) in expected.items():
        assert degrees[name] == pytest.approx((low, high), abs=1e-9)


def test_errors_name_the_urdf_line(tmp_path):
    path = tmp_path / "bad.urdf"
    path.write_text('<robot name="x">\n<link name="a"/>\n<joint name="j" type="fixed">\n<parent link="a"/>\n<child link="zz"/>\n</joint>\n</robot>\n')
    with pytest.raises(InputError) as error:
        read_urdf(path)
    assert error.value.line == 5 and "unknown link 'zz'" in error.value.message
