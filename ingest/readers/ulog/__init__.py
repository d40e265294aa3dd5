"""The reader of PX4 ULog files (through pyulog) and its topic table."""
