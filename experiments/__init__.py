"""The papers' experiments on the DART hexapod: scenario runner, each paper's scenarios, gait
classification, run pictures, paper figures and parameter sweeps on Dask."""
