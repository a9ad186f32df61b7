"""linkevo's figures that a trial, the report, pull and the walk share: a linkage and its
path, a LEGO build's drawings, a repertoire's maps, a walk's pictures (matplotlib, PNG)."""
