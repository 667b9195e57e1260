"""The evaluation engine: a run's saved policies rolled out under chosen or perturbed physics
(`evaluate`), over dynamics grids (`grid`) and named robustness suites (`suites`), in parallel on
local processes or Ray (`parallel`). Its results are files in the run folder that the report reads."""
