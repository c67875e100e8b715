"""LeRobot datasets named by their Hugging Face Hub id (``lerobot/svla_so101_pickplace``), as LeRobot's own tools
name them: resolved to a folder of the user's Hugging Face cache by ``huggingface_hub`` (the optional extra
``framechain[hub]``), fetched only as far as a command needs.

:func:`resolve_dataset` fetches ``meta/`` first, reads from it where the asked episodes' data and videos are
(v3.0: their rows of ``meta/episodes``; v2.x: the path templates of ``meta/info.json``), then fetches those
files alone (``allow_patterns``). The cache is huggingface_hub's (``HF_HOME``, ``HF_HUB_CACHE``), and so is
``HF_HUB_OFFLINE``: offline, the cached snapshot is used as it is. A folder that exists is always read as
that folder, whatever its name looks like. Every failure is one line (:class:`HubError`): an unknown id, a
gated dataset, no network, a revision the Hub lacks, files the cache lacks offline.
"""

from __future__ import annotations

import re
from collections.abc import Collection
from pathlib import Path

from framechain.adapters.errors import AdapterError
from framechain.adapters.lerobot.reader import DatasetReader

__all__ = ["HubError", "is_hub_id", "resolve_dataset"]

#: ``owner/name`` as the Hub spells repository ids (letters, digits, ``-``, ``_``, ``.``; no ``--`` or ``..``).
_HUB_ID = re.compile(r"[A-Za-z0-9][\w.-]{0,95}/[A-Za-z0-9][\w.-]{0,95}")
#: Names that are files framechain reads, never Hub ids.
_LOG_SUFFIXES = (".mcap", ".bag", ".db3", ".yaml", ".yml", ".json", ".parquet")
META_PATTERN = "meta/*"


class HubError(AdapterError):
    """A Hub id that could not be resolved to a dataset folder: built from the id and what is wrong."""


def is_hub_id(text: str) -> bool:
    """Whether ``text`` is spelled as a Hub id (``owner/name``) and names no existing path."""
    return (_HUB_ID.fullmatch(text) is not None and "--" not in text and ".." not in text
            and not text.lower().endswith(_LOG_SUFFIXES) and not Path(text).exists())


def resolve_dataset(spec: str, *, revision: str | None = None, episodes: Collection[int] | None = ()) -> Path:
    """The folder of the dataset ``spec``: ``spec`` itself when it exists (or is no Hub id, for the reader to
    say what is wrong with it), else the Hub dataset of that id at ``revision`` (default: main) in the user's
    Hugging Face cache, with ``meta/`` and the files of ``episodes`` (None: every episode; empty: the first
    episode, so that what is said of the videos holds of the files).
    """
    if not is_hub_id(spec):
        if revision is not None:
            raise HubError(spec, f"--revision {revision} is for Hugging Face Hub ids; this is a local path")
        return Path(spec)
    _check_installed(spec)
    from huggingface_hub import constants

    folder = _snapshot(spec, revision, [META_PATTERN])
    if not (folder / "meta" / "info.json").is_file():
        raise HubError(spec, f"the Hub dataset has no meta/info.json at {revision or 'main'}: not a LeRobot dataset")
    reader = DatasetReader(folder)
    wanted = reader.episodes() if episodes is None else list(episodes) or reader.episodes()[:1]
    located = [reader.episode_patterns(e) for e in wanted]  # each: the data file, then the videos
    patterns = sorted({p for files in located for p in files})
    if not all(any(folder.glob(p)) for p in patterns):
        folder = _snapshot(spec, revision, [META_PATTERN, *patterns])
    # Offline, huggingface_hub returns the snapshot as the cache holds it (it checks it against the repository's
    # file list only where it cached one): the episodes' data must be there. A video may be declared and never
    # uploaded; the reader says so.
    missing = sorted({files[0] for files in located if not any(folder.glob(files[0]))})
    if missing and constants.HF_HUB_OFFLINE:
        raise HubError(spec, f"the data of the episodes asked for is not in the Hugging Face cache ({missing[0]}"
                       f"{', ...' if len(missing) > 1 else ''}) and HF_HUB_OFFLINE is set: fetch it once online, or "
                       "unset HF_HUB_OFFLINE")
    return folder


def _check_installed(spec: str) -> None:
    """huggingface_hub is an optional extra: without it, one line saying how to install it."""
    try:
        import huggingface_hub  # noqa: F401
    except ImportError as err:
        raise HubError(spec, "no such folder; read as a Hugging Face Hub id it needs huggingface_hub: "
                       "pip install 'framechain[hub]'") from err


def _snapshot(spec: str, revision: str | None, patterns: list[str]) -> Path:
    """``snapshot_download`` of the files matching ``patterns``, its exceptions made one line each."""
    from huggingface_hub import constants, errors, snapshot_download

    at = f" at revision {revision}" if revision else ""
    cache = constants.HF_HUB_CACHE
    try:
        return Path(snapshot_download(spec, repo_type="dataset", revision=revision, allow_patterns=patterns))
    except errors.GatedRepoError as err:
        raise HubError(spec, f"a gated dataset: accept its conditions on https://huggingface.co/datasets/{spec} "
                       "and log in (`hf auth login`, or HF_TOKEN)") from err
    except errors.RepositoryNotFoundError as err:
        raise HubError(spec, "no such folder, and no dataset of that id on the Hugging Face Hub (a private one "
                       "needs `hf auth login`, or HF_TOKEN)") from err
    except errors.RevisionNotFoundError as err:
        raise HubError(spec, f"the Hugging Face Hub has no revision {revision!r} of it") from err
    except errors.LocalEntryNotFoundError as err:
        # IncompleteSnapshotError (huggingface_hub >= 1.x) is one: the cache holds some files, not all asked for.
        if isinstance(err, getattr(errors, "IncompleteSnapshotError", ())):
            raise HubError(spec, f"the Hugging Face cache ({cache}) holds it{at} only in part and the Hub cannot be "
                           f"reached: {_first_line(err)}") from err
        if constants.HF_HUB_OFFLINE:
            raise HubError(spec, f"no such folder, and not in the Hugging Face cache ({cache}){at} while "
                           "HF_HUB_OFFLINE is set: fetch it once online, or unset HF_HUB_OFFLINE") from err
        cause = err.__cause__ or err
        raise HubError(spec, f"no such folder; the Hugging Face Hub cannot be reached ({type(cause).__name__}: "
                       f"{_first_line(cause)}) and it is not in the cache ({cache}){at}") from err
    except errors.HfHubHTTPError as err:
        raise HubError(spec, f"the Hugging Face Hub answered: {_first_line(err)}") from err
    except errors.HFValidationError as err:
        raise HubError(spec, f"not a Hugging Face Hub id: {_first_line(err)}") from err


def _first_line(err: BaseException) -> str:
    lines = [line.strip() for line in str(err).splitlines() if line.strip()]
    return lines[0] if lines else type(err).__name__
