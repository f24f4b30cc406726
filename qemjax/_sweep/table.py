"""A sweep's table on disk: read it back (typed, and for CSV also as the text of each row), write it whole
under a temporary name, fsync, rename. A CSV's rows already in the file are written back as the same text,
so a resumed sweep leaves them byte for byte as they were.
"""
from __future__ import annotations

import contextlib
import math
import os
from pathlib import Path

import numpy as np

from .._io import held

FORMATS = {".parquet": "parquet", ".pq": "parquet", ".csv": "csv"}
TEXT_COLUMNS = dict.fromkeys(("error", "cell", "mesh_sha256", "metrics_settings"), str)  # read as text
NOT_APPLICABLE = "n/a"  # a grid key the cell's method does not have (empty / NaN stays "None")


def _format(out) -> str:
    ext = Path(out).suffix.lower()
    if ext not in FORMATS:
        raise ValueError(f"out must end in one of {sorted(FORMATS)}, got {os.fspath(out)!r}")
    return FORMATS[ext]


def _mixed(column) -> bool:
    """Whether a column of objects holds values Parquet cannot store in one column type: more than one kind
    of value (a number beside a text), or lists, tuples or dicts (``attributes``, ``attribute_weights``).
    Such a column is stored as text, as a CSV stores it."""
    if column.dtype != object:
        return False
    kinds = set()
    for v in column:
        if v is None or (isinstance(v, float) and math.isnan(v)):
            continue
        if isinstance(v, (bool, np.bool_)):
            kinds.add("bool")
        elif isinstance(v, (int, float, np.number)):
            kinds.add("number")
        elif isinstance(v, str):
            kinds.add("str")
        else:
            return True
    return len(kinds) > 1


def _check_writable(out) -> str:
    """The format of ``out``; ValueError when its folder does not exist, when it is a folder, when it is
    Parquet and pyarrow is missing, or when its folder takes no new file (`check_folder_takes_files`; the table
    is written under a temporary name there): before anything runs."""
    fmt = _format(out)
    path = Path(out)
    if path.is_dir():
        raise ValueError(f"out is a folder, not a table file: {os.fspath(out)}")
    if not path.absolute().parent.is_dir():
        raise ValueError(f"out's folder does not exist: {os.fspath(path.absolute().parent)}")
    if fmt == "parquet":
        _need_pyarrow(out)
    check_folder_takes_files(out)
    return fmt


def _need_pyarrow(out) -> None:
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        raise ValueError(f"writing {Path(out).name} needs pyarrow (pip install 'qemjax[sweep]'), "
                         "or give a .csv out") from None


def check_folder_takes_files(out) -> None:
    """ValueError naming ``out`` when its (existing) folder takes no new file, read-only or not a real folder:
    found by making and removing an empty file beside it, as the table's temporary file will be, rather than
    after the first cells ran, when the first write of the table would fail."""
    probe = Path(out).absolute().with_name(f".{Path(out).name}.probe-{os.getpid()}")
    try:
        with open(probe, "xb"):
            pass
        os.remove(probe)
    except OSError as exc:
        raise ValueError(f"cannot write {os.fspath(out)}: its folder takes no new file "
                         f"({exc.strerror or exc})") from None


def target_column(values):
    """The ``target`` column as given: ints (face counts) stay ints beside floats (ratios). A target
    >= 1 is always a face count and < 1 a ratio (`check_targets`), so the type follows from the value,
    also when a file stored the column as float (Parquet: one type per column; CSV read back)."""
    import pandas as pd

    vals = [v if isinstance(v, str) else int(v) if v >= 1 else float(v) for v in values]
    kinds = {type(v) for v in vals}
    dtype = "int64" if kinds == {int} else "float64" if kinds == {float} else object
    return pd.Series(vals, dtype=dtype)


def _typed(df):
    if "target" in df and len(df):
        df = df.copy()
        df["target"] = target_column(df["target"]).to_numpy()
    return _not_applicable_back(df)


def _value(text: str):
    """A value of a column that holds "n/a" (so it was stored as text): a number, a bool, or the text."""
    if text in ("True", "False"):
        return text == "True"
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


def _not_applicable_back(df):
    """Columns that hold "n/a" were stored as text: their other values back to numbers / bools."""
    cols = [c for c in df.columns if _marked(df[c])]
    if cols:
        df = df.copy()
        for col in cols:
            df[col] = np.array([v if not isinstance(v, str) or v == NOT_APPLICABLE else _value(v) for v in df[col]],
                               dtype=object)
    return df


def _marked(column) -> bool:
    """Whether a column of text or objects holds "n/a"."""
    import pandas as pd

    return (column.dtype == object or pd.api.types.is_string_dtype(column)) and \
        bool((column.astype(object) == NOT_APPLICABLE).any())


def read_table(out):
    """The table at ``out`` (Parquet or CSV by extension), its ``target`` column as given (`target_column`),
    "n/a" columns' other values as numbers; an empty DataFrame when it does not exist."""
    import pandas as pd

    if not Path(out).exists() or Path(out).stat().st_size == 0:  # an empty file holds no rows yet
        return pd.DataFrame()
    if _format(out) == "csv":
        try:
            df = pd.read_csv(out, keep_default_na=False, na_values=[""], dtype=TEXT_COLUMNS)
        except ValueError as exc:
            raise _unreadable(out, exc) from None
        if "error" in df:  # no error is "", as in the rows a sweep makes (an empty field reads as NaN)
            df["error"] = df["error"].fillna("")
        return _typed(df)
    _need_pyarrow(out)
    try:
        return _typed(pd.read_parquet(out))
    except ValueError as exc:  # pyarrow's ArrowInvalid is one
        raise _unreadable(out, exc) from None
    except OSError as exc:  # a damaged footer; an error of the system's own (errno: permissions) stays as it is
        if exc.errno is not None:
            raise
        raise _unreadable(out, exc) from None


def _unreadable(out, exc: Exception) -> ValueError:
    """The one-line error for a file at ``out`` that cannot be read back as a table (a sweep would resume
    it): the file named, and why in a few words rather than the reader's own (a decoder's byte position,
    pandas' C tokenizer, Parquet's footer)."""
    text = " ".join(str(exc).split())
    if isinstance(exc, UnicodeDecodeError):
        why = "it is not text"
    elif "magic bytes" in text:
        why = "it is not a Parquet file"
    elif text.startswith("Could not open Parquet input source"):  # its beginning and end are a Parquet file's
        why = "it is not a whole Parquet file: cut short or damaged"
    else:
        why = text.replace("Error tokenizing data. C error: ", "")
    return ValueError(f"{os.fspath(out)} exists but is not a sweep table ({why}): give another out, or remove it")


def read_text(out) -> tuple[list[str], dict[str, dict]]:
    """A CSV table's header and each row's fields as the text in the file, by ``cell`` (empty when absent)."""
    import pandas as pd

    if not Path(out).exists() or _format(out) != "csv" or Path(out).stat().st_size == 0:
        return [], {}
    try:
        df = pd.read_csv(out, dtype=str, keep_default_na=False)
    except ValueError as exc:
        raise _unreadable(out, exc) from None
    if "cell" not in df:
        return list(df.columns), {}
    return list(df.columns), {r["cell"]: r for r in df.to_dict("records")}


def as_text(value) -> str:
    """A new row's value as a CSV field: what pandas writes for it (floats by repr, None / NaN empty)."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, np.generic):
        value = value.item()
    return repr(value) if isinstance(value, float) else str(value)


@contextlib.contextmanager
def holding(out):
    """Within it, this sweep alone reads and writes the table ``out`` (`_io.held`: a lock on a hidden file
    beside it, ``.NAME.lock``, removed as it ends); ValueError at once when another sweep holds it. Two
    sweeps writing one table each wrote back only the rows it had read and run itself (the other's were
    lost), through the same temporary file. None: no table, nothing held."""
    if out is None:
        yield
        return
    path = Path(out).with_name(f".{Path(out).name}.lock")
    fd = held.take(path, f"out {os.fspath(out)} is being written by another sweep; wait until it ends, or "
                         "give another out")
    try:
        yield
    finally:
        held.release(path, fd)


def _fsynced_replace(tmp: Path, out) -> None:
    fd = os.open(tmp, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(tmp, out)


def write_text(header: list[str], records: list[dict], out) -> None:
    """Write CSV text rows (column → field text; missing fields empty) under a temporary name, fsync, rename."""
    import pandas as pd

    tmp = Path(out).with_name(f".{Path(out).name}.tmp")
    pd.DataFrame([[r.get(c, "") for c in header] for r in records], columns=header, dtype=object) \
        .to_csv(tmp, index=False)
    _fsynced_replace(tmp, out)


def write_table(df, out) -> None:
    """Write ``df`` to a temporary file next to ``out``, fsync, then rename: an interruption never leaves a
    partial table. CSV keeps integer targets as integers ("424"); Parquet stores a column of ratios and
    face counts as float64 (`read_table` gives them back as ints), and a column that holds "n/a" as text."""
    tmp = Path(out).with_name(f".{Path(out).name}.tmp")
    if _format(out) == "csv":
        _typed(df).to_csv(tmp, index=False)
    else:
        df = df.copy()
        for col in df.columns:
            if _marked(df[col]) or _mixed(df[col]):
                df[col] = [None if v is None or isinstance(v, float) and math.isnan(v) else as_text(v)
                           for v in df[col]]
        df.to_parquet(tmp, index=False)
    _fsynced_replace(tmp, out)
