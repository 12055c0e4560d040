"""canopen's EDS import, once per file and node id in a process.

Parsing an EDS (:func:`canopen.import_od`, configparser underneath) takes 13 ms for the shipped
one; a process that builds several nodes from one file (a simulator of three axes, the suite's
runs) parsed it again for each.  :func:`import_eds` parses a file once per ``(path, node id)``
(the path as given, made absolute, a link's own name kept: canopen tells an EDS by that name's suffix)
and hands out fresh copies (``pickle`` of the dictionary this process built: 0.7 ms), so a
caller may change its dictionary without touching another's.  A file changed on disk is parsed
again: another size, inode, modification time or status-change time (``st_ctime``, which every
write and every ``utime`` moves to now: ``cp -p``, ``tar`` and ``rsync -t`` set an old modification
time on new contents, none can set this one back); a file canopen cannot parse raises as
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
    name = os.path.join(os.getcwd(), path)  # as given, links kept: canopen tells an EDS by its name's suffix
    stat = os.stat(name)  # the file a link leads to: a link moved to another file is another version
    version = (stat.st_dev, stat.st_ino, stat.st_size, stat.st_mtime_ns, stat.st_ctime_ns)
    return pickle.loads(_parsed(name, version, node_id))


@functools.lru_cache(maxsize=32)
def _parsed(name: str, version: tuple[int, int, int, int, int], node_id: int) -> bytes:
    """canopen's dictionary of the file ``name`` as it was at ``version`` (device, inode, size in bytes,
    modification and status-change times in ns), pickled."""
    return pickle.dumps(canopen.import_od(name, node_id), protocol=pickle.HIGHEST_PROTOCOL)
