"""Compiled scanners of text mesh blocks (numba). Each takes a block of bytes ending with a newline and
returns the bytes of the coordinates it found, joined by spaces (numpy's own parser turns them into
float64, correctly rounded), and the triangles it fanned; an error code and the line it is on, else 0.

Lines end at '\\n'; spaces, tabs and '\\r' separate words.
"""
from __future__ import annotations

import numpy as np

from .._mesh.compiled import njit

OK, BAD_VERTEX, BAD_CORNER, ZERO_INDEX, BEFORE_FIRST, FEW_CORNERS, BAD_FACET, FEW_VALUES, BAD_INT = range(9)
NO_UV = -1  # a corner without a texture coordinate number
BAD_UV = -(1 << 62)  # a corner whose texture coordinate number names none (0): the UVs cannot be kept
NL = 10


@njit(cache=True)
def _ws(c):
    return c == 32 or c == 9 or c == 13 or c == 11 or c == 12


@njit(cache=True)
def _digit(c):
    return 48 <= c <= 57


@njit(cache=True)
def _skip_ws(buf, i):
    while _ws(buf[i]):
        i += 1
    return i


@njit(cache=True)
def _word_end(buf, i):
    while not _ws(buf[i]) and buf[i] != NL:
        i += 1
    return i


@njit(cache=True)
def _copy(buf, i, j, out, no):
    """Appends buf[i:j] and a space to out at no; the new length."""
    for k in range(i, j):
        out[no] = buf[k]
        no += 1
    out[no] = 32
    return no + 1


@njit(cache=True)
def _is(buf, i, j, word):
    if j - i != len(word):
        return False
    for k in range(len(word)):
        if buf[i + k] != word[k]:
            return False
    return True


@njit(cache=True)
def _grow(tris, nt, extra):
    if nt + extra <= len(tris):
        return tris
    grown = np.empty((2 * len(tris) + extra, 3), np.int64)
    for r in range(nt):  # an explicit loop: a 2-d slice assignment takes seconds to compile
        for c in range(3):
            grown[r, c] = tris[r, c]
    return grown


@njit(cache=True)
def _coords(buf, i, out, no, words=3):
    """Copies the ``words`` words from buf[i] on to out at no: (offset after them, new length), offset -1
    when the line ends sooner."""
    for _ in range(words):
        i = _skip_ws(buf, i)
        j = _word_end(buf, i)
        if j == i:
            return -1, no
        no = _copy(buf, i, j, out, no)
        i = j
    return i, no


@njit(cache=True)
def _number(buf, k):
    """A whole number from buf[k], optionally negative: (offset after it, value, whether there was one)."""
    neg = buf[k] == 45
    if neg:
        k += 1
    if not _digit(buf[k]):
        return k, 0, False
    v = 0
    while _digit(buf[k]):
        v = v * 10 + np.int64(buf[k] - 48)
        k += 1
    return k, -v if neg else v, True


@njit(cache=True)
def _corner(buf, i):
    """An OBJ corner word from buf[i] (``v``, ``v/t``, ``v//n`` or ``v/t/n``): (offset after it, its vertex
    number, its texture coordinate number (negative: counted back; 0 when it names none, `BAD_UV` for
    ``v/0``), error code)."""
    k, v, ok = _number(buf, i)
    if not ok:
        return k, 0, 0, BAD_CORNER
    t = 0
    if buf[k] == 47 and buf[k + 1] != 47 and not _ws(buf[k + 1]) and buf[k + 1] != NL:  # v/t
        k, t, ok = _number(buf, k + 1)
        if not ok:
            return k, 0, 0, BAD_CORNER
        if t == 0:
            t = BAD_UV
    while not _ws(buf[k]) and buf[k] != NL:  # the normal's number: checked, not kept
        if not (_digit(buf[k]) or buf[k] == 47 or buf[k] == 45):
            return k, 0, 0, BAD_CORNER
        k += 1
    if v == 0:
        return k, 0, 0, ZERO_INDEX
    return k, v, t, OK


@njit(cache=True)
def _face(buf, i, tris, uvs, nt, nv, nvt):
    """Fans the corners of an OBJ face line from buf[i] (``nv`` vertices and ``nvt`` texture coordinates so
    far) into tris and their texture coordinates' numbers into uvs at nt (`NO_UV` for none, `BAD_UV` for
    one that names none: 0, or counted back past the first): (offset at the line's end, triangles, their
    uvs, new count, error code)."""
    k, first, prev, tfirst, tprev = 0, 0, 0, 0, 0
    while True:
        i = _skip_ws(buf, i)
        if buf[i] == NL:
            break
        i, v, t, err = _corner(buf, i)
        if err:
            return i, tris, uvs, nt, err
        v = nv + v if v < 0 else v - 1
        if v < 0:
            return i, tris, uvs, nt, BEFORE_FIRST
        if t == BAD_UV or nvt + t < 0:
            t = BAD_UV
        else:
            t = NO_UV if t == 0 else (nvt + t if t < 0 else t - 1)
        if k == 0:
            first, tfirst = v, t
        elif k >= 2:
            tris = _grow(tris, nt, 1)
            uvs = _grow(uvs, nt, 1)
            tris[nt, 0], tris[nt, 1], tris[nt, 2] = first, prev, v
            uvs[nt, 0], uvs[nt, 1], uvs[nt, 2] = tfirst, tprev, t
            nt += 1
        prev, tprev, k = v, t, k + 1
    return i, tris, uvs, nt, FEW_CORNERS if k < 3 else OK


@njit(cache=True)
def obj(buf, nv0, nvt0):
    """OBJ: `v` lines' first three words, `vt` lines' first two; `f` lines' corners (the vertex number
    before any '/', and the texture coordinate's after it), 1-based or negative (counted back from the
    last so far, ``nv0`` vertices and ``nvt0`` texture coordinates before this block) made 0-based, fanned.
    Returns (coordinate bytes, vertices, triangles, error, error line, texture coordinate bytes, texture
    coordinates, each triangle corner's texture coordinate number or `NO_UV`, whether a `vt` line had
    fewer than two values)."""
    n = len(buf)
    out = np.empty(n + 1, np.uint8)
    uv_out = np.empty(2 * n + 4, np.uint8)  # room for "0 0 " in place of each short line
    tris = np.empty((max(16, n // 16), 3), np.int64)
    uvs = np.empty((max(16, n // 16), 3), np.int64)
    no, nuo, nt, nv, nvt, line, i, err = 0, 0, 0, 0, 0, 0, 0, OK
    uv_short = False
    while i < n and err == OK:
        line += 1
        i = _skip_ws(buf, i)
        j = _word_end(buf, i)
        if j - i == 1 and buf[i] == 118:  # v
            i, no = _coords(buf, j, out, no)
            nv += 1
            if i < 0:
                err = BAD_VERTEX
                break
        elif j - i == 2 and buf[i] == 118 and buf[i + 1] == 116:  # vt
            before = nuo
            k, nuo = _coords(buf, j, uv_out, nuo, 2)
            nvt += 1
            if k < 0:  # fewer than u and v (a 1-d texture): "0 0" in its place keeps the numbering
                uv_short = True
                nuo = before
                for c in (48, 32, 48, 32):
                    uv_out[nuo] = c
                    nuo += 1
            else:
                i = k
        elif j - i == 1 and buf[i] == 102:  # f
            i, tris, uvs, nt, err = _face(buf, j, tris, uvs, nt, nv0 + nv, nvt0 + nvt)
        while buf[i] != NL:
            i += 1
        i += 1
    return out[:no], nv, tris[:nt], err, line, uv_out[:nuo], nvt, uvs[:nt], uv_short


@njit(cache=True)
def stl(buf, pending):
    """ASCII STL: the three words after each `vertex`; ``pending`` vertices of an open facet before
    the block. A facet (at `endloop`) must have three. Returns (coordinate bytes, vertices, lines,
    vertices of the facet still open, error, error line)."""
    n = len(buf)
    out = np.empty(n + 1, np.uint8)
    vertex = np.array([118, 101, 114, 116, 101, 120], np.uint8)
    endloop = np.array([101, 110, 100, 108, 111, 111, 112], np.uint8)
    no, nv, line, i = 0, 0, 0, 0
    while i < n:
        line += 1
        i = _skip_ws(buf, i)
        j = _word_end(buf, i)
        if _is(buf, i, j, vertex):
            i = j
            for _ in range(3):
                i = _skip_ws(buf, i)
                j = _word_end(buf, i)
                if j == i:
                    return out[:no], nv, line, pending, BAD_VERTEX, line
                no = _copy(buf, i, j, out, no)
                i = j
            nv += 1
            pending += 1
        elif _is(buf, i, j, endloop):
            if pending != 3:
                return out[:no], nv, line, pending, BAD_FACET, line
            pending = 0
        while buf[i] != NL:
            i += 1
        i += 1
    return out[:no], nv, line, pending, OK, 0


@njit(cache=True)
def _int_word(buf, i, j):
    """The integer written in buf[i:j], and whether it is one."""
    neg = buf[i] == 45
    k = i + (neg or buf[i] == 43)
    if k == j:
        return 0, False
    v = 0
    for m in range(k, j):
        if not _digit(buf[m]):
            return 0, False
        v = v * 10 + (buf[m] - 48)
    return -v if neg else v, True


@njit(cache=True)
def ply_rows(buf, pos, rows, mode, cols, kinds, index):
    """ASCII PLY rows of one element from byte ``pos``, one non-empty line each, at most ``rows``.
    mode 0: skipped; 1: vertices, whose properties at ``cols`` (x, y, z, and u, v when kept) are kept; 2:
    faces; both walked by ``kinds`` (0 a scalar, 1 a list: a vertex's skipped, a face's ``index`` list
    fanned). Returns (end offset, rows read, coordinate bytes, triangles, lines passed, error, error line)."""
    n = len(buf)
    out = np.empty(n + 1, np.uint8)
    tris = np.empty((max(16, n // 16) if mode == 2 else 0, 3), np.int64)
    no, nt, done, line, i = 0, 0, 0, 0, pos
    spans = np.zeros((len(cols), 2), np.int64)
    while i < n and done < rows:
        line += 1
        i = _skip_ws(buf, i)
        if buf[i] == NL:
            i += 1
            continue
        if mode == 1:
            for p in range(len(kinds)):
                j = _word_end(buf, i)
                if j == i:
                    return i, done, out[:no], tris[:nt], line, FEW_VALUES, line
                if kinds[p] == 1:  # a list: its count, and that many words skipped
                    count, ok = _int_word(buf, i, j)
                    if not ok or count < 0:
                        return i, done, out[:no], tris[:nt], line, BAD_INT, line
                    for _ in range(count):
                        i = _skip_ws(buf, j)
                        j = _word_end(buf, i)
                        if j == i:
                            return i, done, out[:no], tris[:nt], line, FEW_VALUES, line
                else:
                    for c in range(len(cols)):
                        if cols[c] == p:
                            spans[c, 0], spans[c, 1] = i, j
                i = _skip_ws(buf, j)
            for c in range(len(cols)):
                no = _copy(buf, spans[c, 0], spans[c, 1], out, no)
        elif mode == 2:
            for p in range(len(kinds)):
                count = 1
                if kinds[p] == 1:
                    j = _word_end(buf, i)
                    count, ok = _int_word(buf, i, j)
                    if j == i:
                        return i, done, out[:no], tris[:nt], line, FEW_VALUES, line
                    if not ok or count < 0:
                        return i, done, out[:no], tris[:nt], line, BAD_INT, line
                    i = _skip_ws(buf, j)
                    if p == index:
                        tris = _grow(tris, nt, max(count - 2, 0))
                first, prev = 0, 0
                for k in range(count):
                    j = _word_end(buf, i)
                    if j == i:
                        return i, done, out[:no], tris[:nt], line, FEW_VALUES, line
                    if p == index:
                        v, ok = _int_word(buf, i, j)
                        if not ok:
                            return i, done, out[:no], tris[:nt], line, BAD_INT, line
                        if k == 0:
                            first = v
                        elif k >= 2:
                            tris[nt, 0], tris[nt, 1], tris[nt, 2] = first, prev, v
                            nt += 1
                        prev = v
                    i = _skip_ws(buf, j)
        while buf[i] != NL:
            i += 1
        i += 1
        done += 1
    return i, done, out[:no], tris[:nt], line, OK, 0
