"""MCAP: the indexed reader, the salvage scanner for damaged files, and the export that copies a log
into a new MCAP with messages added."""

#: The bytes an MCAP file starts (and ends) with.
MCAP_MAGIC = b"\x89MCAP0\r\n"
