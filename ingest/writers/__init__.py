"""Writers of foreign log formats, used by the synthesizers to emit real log files."""
