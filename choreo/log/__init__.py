"""The run log: its format (topics, records, schemas), the recorder that writes it as MCAP, and
the reader that every review goes through (the triad the mcap library itself has)."""
