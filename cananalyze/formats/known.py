"""Format modules the source facade imports so that each registers its LogFormat."""

FORMAT_MODULES = [
    "mcap",
    "candump",
    "asc",
    "blf",
    "pcap",
    "trc",
    "canbusanalyzer",
    "ixxat",
    "gvret",
    "pycan_csv",
    "sevcon",
    "pycan_fallback",
]
