"""UFF dataset 58 against its specification, not against the library that writes it.

The record below is written by hand from the published field layout of Universal Dataset
Number 58, "Function at Nodal DOF" (SDRC I-DEAS, revision 30-Jun-1999, in the "Universal File
Datasets Summary"; the text kept by the University of Cincinnati Structural Dynamics Research
Lab, https://www.ceas3.uc.edu/sdrluff/files/58.asc, and copied verbatim into pyuff's
``pyuff.datasets.dataset_58.get_structure_58``), and for the binary form from UC-SDRL's
"The Binary 58 Universal File Format" (uff58b.txt). The layout used here:

- every dataset: "    -1" (I6), the dataset number (I6), ..., "    -1";
- records 1-5: ID lines, Format(80A1), "NONE" in columns 1-4 when unused;
- record 6, Format(2(I5,I10),2(1X,10A1,I10,I4)): function type (1 time response), function
  id, version, load case (0 single point excitation), response entity name (10A1, "NONE" if
  unused), response node, response direction (0 scalar, 1 2 3 = +X +Y +Z, -1 -2 -3 opposite),
  reference entity, node and direction;
- record 7, Format(3I10,3E13.5): ordinate data type (2 real single, 4 real double), number of
  values, abscissa spacing (1 even), abscissa minimum, abscissa increment, z-axis value;
- records 8-11, Format(I10,3I5,2(1X,20A1)), abscissa, ordinate, ordinate denominator, z axis:
  specific data type (0 unknown, 8 displacement, 9 reaction force, 11 velocity,
  12 acceleration, 13 excitation force, 17 time), length, force and temperature unit exponents
  (Addendum A's table for a translational direction: 8, 11, 12 -> 1 0 0; 9, 13 -> 0 1 0;
  17 -> 0 0 0; records 10 and 11 unused: type 0), axis label, axis units label;
- record 12, the values: real double even spacing 4E20.12, real single even spacing 6E13.5
  (Addendum B, cases 5 and 1);
- 58b: the identifier record Format(I6,1A1,I6,I6,I12,I12,I6,I6,I12,I12): 58, "b", byte order
  (1 little-endian, 2 big-endian), floating-point format (2 IEEE 754), ASCII lines following
  (11), bytes following them, four zeros; then records 1-11 as above, the values as raw
  binary numbers in record 12's order, and "    -1" right after them.

The numbers are written as Fortran writes E fields (0.d mantissa, right-justified), unlike
Python's, so a reader that only understands its own writer's output would fail here.
"""

from __future__ import annotations

import struct
import sys

import numpy as np
import pytest

from fem.uff import TimeHistory, read_uff58, write_uff58
from reduced.models.loads import read_force_history

# Three channels of a hammer test, by hand: the hammer's force at node 300 along -Z in double
# precision (t0 = 2 ms), an accelerometer along +Z at node 3 in single precision, a load cell's
# reaction force along -Z at node 202 in double precision; dt = 50 us.
HAND = """\
    -1
    58
hammer
bearingshaft
NONE
NONE
NONE
    1         0    0         0 hammer           300  -3 NONE               0   0
         4         6         1  0.20000E-02  0.50000E-04  0.00000E+00
        17    0    0    0 NONE                 s
        13    0    1    0 NONE                 N
         0    0    0    0 NONE                 NONE
         0    0    0    0 NONE                 NONE
  0.000000000000E+00  0.125500000000E+03  0.250000000000E+03  0.500000000000E+03
  0.250000000000E+03 -0.325000000000E-02
    -1
    -1
    58
beam_s3:z
bearingshaft
NONE
NONE
NONE
    1         0    0         0 beam_s3:z          3   3 NONE               0   0
         2         7         1  0.00000E+00  0.50000E-04  0.00000E+00
        17    0    0    0 NONE                 s
        12    1    0    0 NONE                 m/s^2
         0    0    0    0 NONE                 NONE
         0    0    0    0 NONE                 NONE
  0.10000E+01 -0.20000E+01  0.35000E+01  0.12500E+00 -0.40000E+02  0.10000E+04
  0.50000E+00
    -1
    -1
    58
tip_left_bottom
bearingshaft
NONE
NONE
NONE
    1         0    0         0 tip_left_b       202  -3 NONE               0   0
         4         3         1  0.00000E+00  0.50000E-04  0.00000E+00
        17    0    0    0 NONE                 s
         9    0    1    0 NONE                 N
         0    0    0    0 NONE                 NONE
         0    0    0    0 NONE                 NONE
  0.000000000000E+00  0.875000000000E+02 -0.100000000000E+01
    -1
"""

# (name, node, direction, quantity, values, t0) of the three records above
EXPECTED = [
    ("hammer", 300, -3, "force", [0.0, 125.5, 250.0, 500.0, 250.0, -3.25e-3], 2e-3),
    ("beam_s3:z", 3, 3, "acceleration", [1.0, -2.0, 3.5, 0.125, -40.0, 1000.0, 0.5], 0.0),
    ("tip_left_bottom", 202, -3, "reaction_force", [0.0, 87.5, -1.0], 0.0),
]
DT = 5e-5

# the fixed-column layout of records 6-11, from the Fortran formats: (width, kind), kind
# i = integer (I), e = real (E), a = characters (A), x = a blank (1X)
RECORD6 = [(5, "i"), (10, "i"), (5, "i"), (10, "i"), (1, "x"), (10, "a"), (10, "i"), (4, "i"),
           (1, "x"), (10, "a"), (10, "i"), (4, "i")]
RECORD7 = [(10, "i"), (10, "i"), (10, "i"), (13, "e"), (13, "e"), (13, "e")]
RECORD8 = [(10, "i"), (5, "i"), (5, "i"), (5, "i"), (1, "x"), (20, "a"), (1, "x"), (20, "a")]
HEADER_58B = [(6, "i"), (1, "a"), (6, "i"), (6, "i"), (12, "i"), (12, "i"), (6, "i"), (6, "i"), (12, "i"),
              (12, "i")]


def fields(line: str, layout) -> list[str]:
    """The fields of ``line`` (padded to 80 columns) cut at the layout's column widths."""
    line = line.rstrip("\n").ljust(80)
    out, col = [], 0
    for width, _kind in layout:
        out.append(line[col:col + width])
        col += width
    return out


def records(text: str) -> list[list[str]]:
    """The lines of each dataset between its "    -1" delimiters (the identifier line first)."""
    lines = text.splitlines()
    out, k = [], 0
    while k < len(lines):
        assert lines[k] == "    -1", (k, lines[k])
        end = lines.index("    -1", k + 1)
        out.append(lines[k + 1:end])
        k = end + 1
    return out


def values(lines: list[str], width: int) -> list[float]:
    """Record 12's numbers: each line cut into fields of ``width`` columns (4E20.12 or 6E13.5)."""
    out = []
    for line in lines:
        assert len(line) % width == 0 and len(line) <= 80, line
        out += [float(line[c:c + width]) for c in range(0, len(line), width)]
    return out


def _check_layout(rec: list[str]) -> None:
    """Blank 1X columns are blank, numeric fields are right-justified (Fortran I and E output)."""
    for line, layout in [(rec[6], RECORD6), (rec[7], RECORD7), *[(r, RECORD8) for r in rec[8:12]]]:
        assert len(line) <= 80
        for text, (_w, kind) in zip(fields(line, layout), layout, strict=True):
            if kind == "x":
                assert text == " ", line
            elif kind in "ie":
                assert text.strip() and text[-1] != " ", (line, text)


def test_the_hand_written_record_follows_the_layout():
    """The literal itself: 11 header records in the fixed columns, ID lines of 80A1 at most."""
    recs = records(HAND)
    assert len(recs) == 3
    for rec, (name, *_rest) in zip(recs, EXPECTED, strict=True):
        assert rec[0] == "    58"
        assert rec[1] == name and all(len(line) <= 80 for line in rec[1:6])
        _check_layout(rec)


def test_the_reader_reads_the_hand_written_record(tmp_path):
    path = tmp_path / "hand.uff"
    path.write_text(HAND)
    chans = read_uff58(path)
    assert [c.name for c in chans] == [e[0] for e in EXPECTED]
    for ch, (name, node, direction, quantity, data, t0) in zip(chans, EXPECTED, strict=True):
        assert (ch.node, ch.direction, ch.quantity) == (node, direction, quantity), name
        assert ch.dt_s == DT and ch.t0_s == t0, name
        np.testing.assert_array_equal(ch.data, data)  # every value is exact in its digits
    # the force_file reader picks the excitation force (type 13) among the records
    t, p = read_force_history(path)
    np.testing.assert_array_equal(p, EXPECTED[0][4])
    np.testing.assert_allclose(t, 2e-3 + DT * np.arange(6), rtol=0, atol=1e-18)


def test_the_reader_does_not_need_the_exponents_of_a_known_data_type(tmp_path):
    """Addendum A: for a specific data type other than 1 (general) the exponents "should not be
    supplied" and the table's are used; files from test systems write them as 0 0 0."""
    text = HAND.replace("        12    1    0    0", "        12    0    0    0")
    text = text.replace("        13    0    1    0", "        13    0    0    0")
    path = tmp_path / "zeros.uff"
    path.write_text(text)
    assert [c.quantity for c in read_uff58(path)] == [e[3] for e in EXPECTED]


def _channels() -> list[TimeHistory]:
    return [TimeHistory(name, node, direction, quantity, np.array(data), DT, t0)
            for name, node, direction, quantity, data, t0 in EXPECTED]


def test_the_writer_writes_the_hand_written_record_field_by_field(tmp_path):
    """The project's ASCII output against the hand-written record: the same text in every
    field of records 1-11 (codes, node, direction sign, unit exponents, labels, and the 10A1
    entity names left-justified as Fortran stores a CHARACTER*10), the same numbers in the E13.5
    fields of record 7 and in record 12. The writer writes every record in double precision
    (ordinate type 4, 4E20.12), which the spec allows; the hand-written accelerometer record is
    single precision (type 2, 6E13.5), so there those two differ and the values agree to its 6
    digits."""
    path = tmp_path / "written.uff"
    write_uff58(path, _channels(), binary=False)
    mine, hand = records(path.read_text()), records(HAND)
    assert len(mine) == len(hand)
    for k, (m, h) in enumerate(zip(mine, hand, strict=True)):
        name = EXPECTED[k][0]
        assert m[0].rstrip() == h[0]  # the identifier record: 58 in columns 1-6
        for j in range(1, 6):  # ID lines: text in columns 1-80
            assert m[j].rstrip() == h[j], (name, j + 1, m[j], h[j])
        _check_layout(m)
        assert fields(m[6], RECORD6) == fields(h[6], RECORD6), (name, m[6], h[6])
        fm, fh = fields(m[7], RECORD7), fields(h[7], RECORD7)
        single = int(fh[0]) == 2
        assert int(fm[0]) == 4 and int(fm[0]) == int(fh[0]) + 2 * single, name  # real double
        assert [int(f) for f in fm[1:3]] == [int(f) for f in fh[1:3]], name  # count, even spacing
        assert [float(f) for f in fm[3:]] == [float(f) for f in fh[3:]], name  # t0, dt, z
        for j in range(8, 12):  # records 8-11: type, exponents, labels
            assert [f.strip() for f in fields(m[j], RECORD8)] == [f.strip() for f in fields(h[j], RECORD8)], \
                (name, j + 1, m[j], h[j])
        written = values(m[12:], 20)
        np.testing.assert_array_equal(written, values(h[12:], 13 if single else 20))
        assert all(len(line) == 80 for line in m[12:-1])  # four values a line, the last line may be short


def test_the_binary_record_follows_the_58b_layout(tmp_path):
    path = tmp_path / "binary.uff"
    chans = _channels()
    write_uff58(path, chans)
    ascii_recs = records(HAND)
    raw = path.read_bytes()
    pos = 0
    for ch, rec in zip(chans, ascii_recs, strict=True):
        head = raw[pos:].split(b"\n", 13)
        assert head[0] == b"    -1"
        f = fields(head[1].decode(), HEADER_58B)
        assert f[1] == "b"
        ints = [int(f[i]) for i in (0, 2, 3, 4, 5, 6, 7, 8, 9)]
        order = 1 if sys.byteorder == "little" else 2
        assert ints == [58, order, 2, 11, 8 * ch.data.size, 0, 0, 0, 0], head[1]
        for j in range(2, 13):  # records 1-11 as in the ASCII form
            line = head[j].decode()
            if j == 8:  # record 7: double precision, whatever the hand-written record says
                assert [float(f) for f in fields(line, RECORD7)[1:]] == [float(f) for f in fields(rec[7], RECORD7)[1:]]
                assert int(fields(line, RECORD7)[0]) == 4
            elif j == 7:
                assert fields(line, RECORD6) == fields(rec[6], RECORD6)
            elif j in (9, 10, 11, 12):
                assert [s.strip() for s in fields(line, RECORD8)] == [s.strip() for s in fields(rec[j - 1], RECORD8)]
            else:
                assert line.rstrip() == rec[j - 1]
        start = pos + sum(len(h) + 1 for h in head[:13])
        n = 8 * ch.data.size
        fmt = "<" if order == 1 else ">"
        assert raw[start:start + n] == struct.pack(f"{fmt}{ch.data.size}d", *ch.data)
        assert raw[start + n:start + n + 7] == b"    -1\n"  # right after the data, no line break before it
        pos = start + n + 7
    assert pos == len(raw)
    back = read_uff58(path)
    for ch, b in zip(chans, back, strict=True):
        np.testing.assert_array_equal(b.data, ch.data)
        assert (b.node, b.direction, b.quantity, b.dt_s, b.t0_s) == (ch.node, ch.direction, ch.quantity, DT, ch.t0_s)


@pytest.mark.parametrize("direction", [-3, -2, -1, 0, 1, 2, 3])
def test_direction_codes_keep_their_sign(tmp_path, direction):
    """Record 6 field 7 in columns 52-55 (I4), negative for the opposite sense."""
    path = tmp_path / "dir.uff"
    write_uff58(path, [TimeHistory("a", 7, direction, "acceleration", np.ones(2), DT)], binary=False)
    line = records(path.read_text())[0][6]
    assert int(fields(line, RECORD6)[7]) == direction
    assert read_uff58(path)[0].direction == direction
