"""Input and output: configuration files and results files."""

from .config import Config, ConfigError, load_config, parse_config
from .results import RESUME_VARIABLE, open_results, run_to_file, write_results

__all__ = ["RESUME_VARIABLE", "Config", "ConfigError", "load_config", "open_results",
           "parse_config", "run_to_file", "write_results"]
