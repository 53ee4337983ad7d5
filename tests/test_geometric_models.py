"""The Table 3.3 front axle (spec geometry §4.9): structure and geometry as documented (built
and validated; no solve here: a model build's validation is already a compile)."""

import numpy as np

from diffsusp.models._front_axle_table_3_3 import (
    TABLE_3_3_AXES,
    TABLE_3_3_CENTRES,
    front_axle_table_3_3,
)


def test_table_3_3_front_axle():
    mech = front_axle_table_3_3()
    assert 6 * len(mech.parts) == 42
    assert mech.joints.n_rows + len(mech.drivers.names) == 42  # kinematic: no DOF left
    pos = np.asarray(mech.markers.position)
    ori = np.asarray(mech.markers.orientation)
    for k, name in enumerate(mech.joints.names):
        i, j = mech.joints.i_marker[k], mech.joints.j_marker[k]
        if name in TABLE_3_3_CENTRES:
            np.testing.assert_array_equal(pos[i], TABLE_3_3_CENTRES[name])
            np.testing.assert_array_equal(pos[j], TABLE_3_3_CENTRES[name])
        if name in TABLE_3_3_AXES:
            axis = np.asarray(TABLE_3_3_AXES[name]) / np.linalg.norm(TABLE_3_3_AXES[name])
            np.testing.assert_allclose(ori[j][:, 2], axis, atol=1e-15)
