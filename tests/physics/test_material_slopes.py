"""The steel's table slopes (twin.physics.materials.Steel): d c_p/dT and d lambda/dT against central differences of
the tables' own interpolation, the interval a table node belongs to, zero beyond the table (issue 21 keeps the
slopes per interval instead of differencing the table on every call)."""

from __future__ import annotations

import numpy as np

from twin.config import small_config
from twin.physics.materials import Steel


def test_slopes_are_the_interpolations_derivatives() -> None:
    steel = Steel.from_config(small_config())
    grid = steel.temperatures
    mids = 0.5 * (grid[1:] + grid[:-1])  # inside each interval the interpolation is linear: the difference is exact
    h = 1e-3
    for value, slope in ((steel.heat_capacity, steel.heat_capacity_slope),
                         (steel.conductivity, steel.conductivity_slope)):
        fd = (value(mids + h) - value(mids - h)) / (2 * h)
        np.testing.assert_allclose(slope(mids), fd, rtol=1e-6, atol=1e-9)
        # a table node takes the interval to its right (the last node the last interval); beyond the table: 0
        np.testing.assert_array_equal(slope(grid[:-1]), slope(mids))
        assert slope(grid[-1]) == slope(mids[-1])
        assert slope(grid[0] - 5.0) == 0.0 and slope(grid[-1] + 5.0) == 0.0
        assert slope(np.array([[mids[0], mids[-1]]])).shape == (1, 2)
    # the two tables differ, so a slope read from the wrong table would show
    assert not np.allclose(steel.heat_capacity_slope(mids), steel.conductivity_slope(mids))

