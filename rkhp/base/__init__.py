"""The base room: errors and input limits, documents and their JSON form, the safe expression
reader, exact text, LaTeX, executors (process pools and Dask) and arithmetic modulo primes.
Nothing here imports another room of rkhp."""
