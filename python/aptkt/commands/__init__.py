"""Sub-commands of the ``aptkt`` command line, one module each (see :mod:`aptkt.cli`)."""
