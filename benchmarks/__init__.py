"""Development benchmarks of bayes_amb: speed (run_all.py) and the foreign generator with its
scoring (foreign/). Never imported by the product."""
