"""Exchange with other codes' formats: FClib (:mod:`.fclib` the file format, :mod:`.fclib_scene` our scenes
as FClib problems, :mod:`.fclib_solve` FClib problems solved and certified, :mod:`.fclib_cli` the command)."""
