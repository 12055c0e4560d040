"""canopen's EDS import, once per file and node id in a process.

Parsing an EDS (:func:`canopen.import_od`, configparser underneath) takes 13 ms for the shipped
one; a process that builds several nodes from one file (a simulator of three axes, the suite's
runs) parsed it again for each.  :func:`import_eds` parses a file once per ``(path, node id)``
and hands out fresh copies (``pickle`` of the dictionary this process built: 0.7 ms), so a
caller may change its dictionary without touching another's.  A file changed on disk (another
size or modification time) is parsed again; a file canopen cannot parse raises as
:func:`canopen.import_od` does, every time.
"""

from __future__ import annotations

import functools
import os
import pickle

import canopen
from canopen import objectdictionary as od


def import_eds(path: str | os.PathLike[str], node_id: int) -> od.ObjectDictionary:
    """The object dictionary of the EDS or DCF at ``path`` with ``$NODEID`` resolved for ``node_id``: a
    dictionary of the caller's own."""
    name = os.path.realpath(path)
    stat = os.stat(name)
    return pickle.loads(_parsed(name, stat.st_mtime_ns, stat.st_size, node_id))


@functools.lru_cache(maxsize=32)
def _parsed(name: str, mtime_ns: int, size: int, node_id: int) -> bytes:
    """canopen's dictionary of the file ``name`` as it was at ``mtime_ns`` and ``size``, pickled."""
    return pickle.dumps(canopen.import_od(name, node_id), protocol=pickle.HIGHEST_PROTOCOL)
