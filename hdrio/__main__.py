"""``python -m hdrio`` and the installed ``hdrio`` command: :func:`run`."""

from hdrio.parallel import blas_on_one_thread


def run() -> None:
    """The ``hdrio`` command (:func:`hdrio.cli.run`), its BLAS pools kept to one thread
    unless the user sized them (:data:`hdrio.parallel.BLAS_POOLS`): set here, before
    anything imports NumPy, whose OpenBLAS sizes its pool when it loads."""
    blas_on_one_thread()
    from hdrio.cli import run as command

    command()


if __name__ == "__main__":
    run()
