"""What the tests share and are not tests themselves: generated scenes and datasets, independent reference
maths, readers of what framechain writes, and the real logs' paths. Imported as ``tests.helpers.NAME``."""
