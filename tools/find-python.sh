#!/usr/bin/env bash
# Print the path of a working Python >= 3.12, or fail with a clear message.
# Order: python3.13 / python3.12 / python3 on PATH (only if they really run),
# then the newest >= 3.12 under `pyenv root`.
set -u
ok() { "$1" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 12) else 1)' >/dev/null 2>&1; }
for cand in python3.13 python3.12 python3; do
  p=$(command -v "$cand" 2>/dev/null) || continue
  if ok "$p"; then echo "$p"; exit 0; fi
done
root=$(pyenv root 2>/dev/null || echo "${PYENV_ROOT:-$HOME/.pyenv}")
for d in $(ls -d "$root"/versions/3.* 2>/dev/null | sort -t. -k2,2nr -k3,3nr); do
  p="$d/bin/python3"
  if [ -x "$p" ] && ok "$p"; then echo "$p"; exit 0; fi
done
echo "find-python: no Python >= 3.12 found (tried python3.13, python3.12, python3 on PATH and $root/versions); install one, e.g. 'pyenv install 3.12'" >&2
exit 1
