"""Parameter studies: :mod:`.grid` runs every combination of given values as Dask tasks (``study grid``)."""
