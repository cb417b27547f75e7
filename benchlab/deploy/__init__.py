"""`benchlab deploy`: a model file, its identified parameters, its observer and the wear law as a C99 module for a
transmission control unit (`generate`), and the software-in-the-loop proof against benchlab's own observer
(`verify`). docs/deploy.md."""
