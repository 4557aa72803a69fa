"""pytest set-up shared by tests/ and the doctests: the BLAS/OpenMP thread limit the CLI
applies (bayes_amb.threads, BAYES_AMB_THREADS, default 1), before numpy is imported."""

from bayes_amb.threads import configure_process

configure_process()
