"""drives.canopen.eds_import: one parse per file and node id, a dictionary of its own for every caller,
a file changed on disk parsed again, a file canopen cannot parse refused every time."""

from __future__ import annotations

import configparser
import os
import pathlib
import shutil

import canopen
import pytest

from drives.canopen.eds_import import import_eds
from sim_drive.eds import eds_path


def _objects(dictionary: canopen.ObjectDictionary) -> dict[tuple[int, int], tuple[str, int, object]]:
    """Every variable's name, data type and default, by (index, subindex)."""
    found = {}
    for index in dictionary.indices:
        obj = dictionary[index]
        for variable in (obj.values() if hasattr(obj, "values") else [obj]):
            found[(variable.index, variable.subindex)] = (variable.name, variable.data_type, variable.default)
    return found


def test_each_caller_gets_canopens_dictionary_of_its_own() -> None:
    first, second = import_eds(eds_path(), 5), import_eds(eds_path(), 5)
    assert first is not second and first[0x6041] is not second[0x6041]
    assert _objects(first) == _objects(canopen.import_od(str(eds_path()), 5)) == _objects(second)
    first[0x6071].default = 123  # one caller's change stays its own
    assert second[0x6071].default != 123 and import_eds(eds_path(), 5)[0x6071].default != 123


def test_node_ids_resolve_apart() -> None:
    five, seven = import_eds(eds_path(), 5), import_eds(eds_path(), 7)
    assert five[0x1800][1].default == 0x180 + 5 and seven[0x1800][1].default == 0x180 + 7  # $NODEID + 0x180


def test_a_file_changed_on_disk_is_read_again(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "drive.eds"
    shutil.copy(eds_path(), path)
    assert "Statusword" == import_eds(path, 5)[0x6041].name
    text = path.read_text().replace("ParameterName=Statusword", "ParameterName=Status word")
    path.write_text(text)
    os.utime(path, ns=(path.stat().st_atime_ns, path.stat().st_mtime_ns + 1_000_000))  # a later time, whatever the clock
    assert "Status word" == import_eds(path, 5)[0x6041].name


def test_a_file_canopen_cannot_parse_raises_every_time(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "broken.eds"
    path.write_text("[1000]\nParameterName=Device type\n[1000]\n")  # a section twice: configparser refuses it
    for _ in range(2):
        with pytest.raises(configparser.DuplicateSectionError):
            import_eds(path, 5)


def test_a_file_changed_with_its_time_and_size_kept_is_read_again(tmp_path: pathlib.Path) -> None:
    # cp -p, tar and rsync -t put a file's old modification time on new contents: a same-size edit
    # (one default digit) copied over with the first file's time must not be the first file's dictionary
    path, edited = tmp_path / "drive.eds", tmp_path / "edited.eds"
    shutil.copy(eds_path(), path)
    text = path.read_text()
    assert "ParameterName=Statusword" in text
    edited.write_text(text.replace("ParameterName=Statusword", "ParameterName=StatusWord"))
    assert edited.stat().st_size == path.stat().st_size
    assert "Statusword" == import_eds(path, 5)[0x6041].name
    kept = path.stat()
    shutil.copyfile(edited, path)
    os.utime(path, ns=(kept.st_atime_ns, kept.st_mtime_ns))  # the time cp -p would have kept
    assert (path.stat().st_mtime_ns, path.stat().st_size) == (kept.st_mtime_ns, kept.st_size)
    assert "StatusWord" == import_eds(path, 5)[0x6041].name


def test_a_file_is_read_by_the_name_it_is_given(tmp_path: pathlib.Path) -> None:
    # canopen tells an EDS by its name's suffix: a link drive.eds to a file named otherwise (a version kept by
    # its name) is an EDS, as canopen.import_od reads it; the link moved to another file is that file
    versions = [tmp_path / "drive.eds.v1", tmp_path / "drive.eds.v2"]
    shutil.copy(eds_path(), versions[0])
    versions[1].write_text(versions[0].read_text().replace("ParameterName=Statusword", "ParameterName=StatusWord"))
    link = tmp_path / "drive.eds"
    link.symlink_to(versions[0])
    assert import_eds(link, 5)[0x6041].name == canopen.import_od(str(link), 5)[0x6041].name == "Statusword"
    link.unlink()
    link.symlink_to(versions[1])
    assert import_eds(link, 5)[0x6041].name == "StatusWord"
    with pytest.raises(ValueError, match="'v2' format"):
        import_eds(versions[1], 5)  # by its own name it is no EDS, to canopen as here
