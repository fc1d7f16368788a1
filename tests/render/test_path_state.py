"""The renderer's path state: the layouts of the packet's work arrays."""

from brdf.render import _integrator as I
from brdf.render import _intersect as X


def test_layouts_name_consecutive_blocks():
    """Each named block of rows starts where the one before it ends, the names are the module's
    row constants, and the ray comes first where trace_packet reads the array as rays."""
    for layout, rows in ((I.FLOAT_LAYOUT, I.FLOAT_ROWS), (I.INT_LAYOUT, I.INT_ROWS),
                         (I.SHADOW_LAYOUT, I.SHADOW_ROWS)):
        first = 0
        for name, width, what in layout:
            assert width > 0 and what, name
            assert getattr(I, name) == first, (name, getattr(I, name), first)
            first += width
        assert first == rows
        names = [name for name, _, _ in layout]
        assert len(set(names)) == len(names)
    for layout in (I.FLOAT_LAYOUT, I.SHADOW_LAYOUT):
        assert layout[0][:2] == ("RAY", X.RAY_ROWS)
    assert (I.O, I.D) == (X.ORIGIN, X.DIRECTION)
    assert I.U + I.ROULETTE == I.FLOAT_ROWS - 1
