"""The oil-spill response apps: perimeter planning, pPathAssign, pCoordinates, oil sensing and fusion."""
