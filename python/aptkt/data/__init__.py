"""Data sets: recordings and features in HDF5 (:mod:`aptkt.data.store`, layout in
:mod:`aptkt.data.schema`). Storage only: generating data sets on the simulated world and
collecting them on a robot are in :mod:`aptkt.runtime`."""

from aptkt.data.schema import SCHEMA, SCHEMA_VERSION
from aptkt.data.store import (
    DatasetError,
    DatasetReader,
    DatasetWriter,
    repair,
    store_features,
    write_features,
)

__all__ = [
    "SCHEMA",
    "SCHEMA_VERSION",
    "DatasetError",
    "DatasetReader",
    "DatasetWriter",
    "repair",
    "store_features",
    "write_features",
]
