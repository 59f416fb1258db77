"""Bundled examples: TOML configurations of the paper's Figs. 3-5 and the Fig. 2 script."""
