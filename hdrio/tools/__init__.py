"""What the commands offer beside the merge job: the built-in sample (``hdrio demo``) and
the synthetic scenes it and the tests render, the chain's image operations, pictures of a
merge (the ``plot`` extra) and the compile-ahead helper process (:mod:`hdrio.jit`).

Nothing below :mod:`hdrio.job` imports this package.
"""
