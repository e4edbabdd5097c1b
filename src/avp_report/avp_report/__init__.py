"""The report of one experiment run (paper Table I).

:mod:`.summary` (the run's table beside the paper's), :mod:`.plots` (its figures, matplotlib) and :mod:`.paper` (the
paper's Table I, ``paper_table_i.csv``). Nothing here imports rclpy.
"""
