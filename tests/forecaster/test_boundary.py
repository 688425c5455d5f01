"""What is pushed for a forecast: one ring enclosing every part that matters."""
import shapely
from shapely.geometry import MultiPolygon, Point, Polygon

from oilspill_moos.forecaster.boundary import outline
from oilspill_moos.forecaster.features import to_lonlat


def test_one_part_gives_its_open_exterior_ring():
    ring = outline(to_lonlat(Point(0, 0).buffer(3_000, quad_segs=8)))
    assert len(ring) == 32 and ring[0] != ring[-1]


def test_several_parts_give_the_outline_enclosing_all_but_slivers():
    lobes = to_lonlat(MultiPolygon([Point(0, 0).buffer(1_000, quad_segs=8), Point(9_000, 0).buffer(3_000, quad_segs=8),
                                    Point(-30_000, 0).buffer(200, quad_segs=8)]))     # a sliver: 1 % of the area
    ring = Polygon(outline(lobes))
    for x in (0, 9_000):
        assert ring.contains(to_lonlat(Point(x, 0)))
    assert not ring.contains(to_lonlat(Point(-30_000, 0)))
    assert ring.is_valid and shapely.get_num_interior_rings(ring) == 0
