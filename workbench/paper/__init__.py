"""The 2003 paper's numerical section: its figures from result Datasets (:mod:`.figures`) and the reproduction
of its test problems 1–5 with the numbers the paper reports (:mod:`.reproduction`, ``workbench reproduce``)."""
