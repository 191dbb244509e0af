"""Studies on top of every stage: the performance benchmark (``bench``), what sets the
step count (``steps``) and work against precision (``precision``). Nothing below imports
this package."""
