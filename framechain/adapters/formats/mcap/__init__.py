"""MCAP: the indexed reader, the salvage scanner for damaged files, and the export that copies a log
into a new MCAP with messages added."""
