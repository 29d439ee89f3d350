"""Input files that hold no data (openfdk.io.placeholders): an empty file and a Git LFS
pointer (what a repository cloned without Git LFS holds where a large file was) are named
as such by every reader, in one line, instead of as a malformed file of the format."""

from __future__ import annotations

import pytest

from openfdk.io.c3d import read_c3d
from openfdk.io.force_plates import read_force_plates
from openfdk.io.meshfiles import read_display_mesh
from openfdk.io.opensim import read_osim
from openfdk.io.storage import read_storage
from openfdk.io.trc import read_trc
from openfdk.io.yamlfile import read_yaml

POINTER = "version https://git-lfs.github.com/spec/v1\noid sha256:4d7a214614ab2935c943f9e0ff69d22eadbb8f32b1258daaa5e2ca24d17e2393\nsize 1961899\n"
LFS = "is a Git LFS pointer, not the file's content: its repository was cloned without its large files " \
      "(run 'git lfs pull' there)"
READERS = [(read_c3d, ".c3d"), (read_force_plates, ".c3d"), (read_trc, ".trc"), (read_storage, ".mot"),
           (read_osim, ".osim"), (read_display_mesh, ".stl"), (read_display_mesh, ".vtp"), (read_display_mesh, ".obj"),
           (read_yaml, ".yaml")]


@pytest.mark.parametrize("content, words", [(POINTER, LFS), ("", "the file is empty")], ids=["lfs", "empty"])
@pytest.mark.parametrize("reader, suffix", READERS, ids=[f"{r.__name__}{s}" for r, s in READERS])
def test_every_reader_names_a_file_that_holds_no_data(tmp_path, reader, suffix, content, words):
    path = tmp_path / f"trial{suffix}"
    path.write_text(content)
    with pytest.raises(ValueError) as info:          # C3DError, TRCError, OsimError are ValueErrors
        reader(path)
    message = str(info.value)
    assert "\n" not in message and message.endswith(f"{path.name}: {words}"), message
