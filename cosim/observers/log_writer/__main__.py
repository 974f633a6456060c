"""``python -m cosim.observers.log_writer``: the log's writer process as a new interpreter
(:func:`cosim.observers.log_writer.process.main`); it leaves as every child does (:func:`cosim.errors.exit_now`)."""

from ...errors import exit_now
from .process import main

if __name__ == "__main__":
    exit_now(main())
