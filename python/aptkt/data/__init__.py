"""Data sets: recordings and features in HDF5. The crash-safe store (:mod:`aptkt.data.store`),
its layout (:mod:`aptkt.data.schema`), recordings as it holds them (:mod:`aptkt.data.codec`),
the features cached beside them (:mod:`aptkt.data.features`), how a file is created whole and
one left empty recognised (:mod:`aptkt.data.atomic`), how damage is found
(:mod:`aptkt.data.integrity`) and what it needs of HDF5 below h5py (:mod:`aptkt.data.hdf5`). Storage only: generating data sets on the simulated world and
collecting them on a robot are in :mod:`aptkt.runtime`."""

from aptkt.data.features import store_features, write_features
from aptkt.data.schema import SCHEMA, SCHEMA_VERSION
from aptkt.data.store import DatasetReader, DatasetWriter, repair
from aptkt.errors import DatasetError  # with the other errors; importable from here too

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
