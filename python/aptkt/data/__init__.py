"""Data sets: recordings and features in HDF5, in a crash-safe store, module by module:

- :mod:`aptkt.data.writer`: appending recordings, each intact once its append returns
- :mod:`aptkt.data.reader`: reading, also while a writer runs or after it died
- :mod:`aptkt.data.recovery`: making a file whose writer died appendable again
- :mod:`aptkt.data.schema`: the layout, and which versions this aptkt reads and writes
- :mod:`aptkt.data.codec`: recordings as the store holds them
- :mod:`aptkt.data.features`: the features cached beside them
- :mod:`aptkt.data.atomic`: a file created whole, and one left empty recognised
- :mod:`aptkt.data.lock`: one writer per data set, across processes
- :mod:`aptkt.data.integrity`: how damage is found
- :mod:`aptkt.data.hdf5`: what the store needs of HDF5 below h5py

Storage only: generating data sets on the simulated world and collecting them on a robot are in
:mod:`aptkt.runtime`."""

from aptkt.data.features import store_features, write_features
from aptkt.data.reader import DatasetReader
from aptkt.data.recovery import repair
from aptkt.data.schema import SCHEMA, SCHEMA_VERSION
from aptkt.data.writer import DatasetWriter
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
