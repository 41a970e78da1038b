"""Files: HDF5 results, viewer files, safe replacement of file sets."""
