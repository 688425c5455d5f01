"""Marine and oil-spill mission apps, perimeter planning, geodesy and the LTC forecaster."""
