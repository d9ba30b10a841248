// Segmented volumes on disk: a folder of PNG slices (binary or labelled, libpng) and NRRD (attached .nrrd or
// detached .nhdr + raw data). Every error names the file (and for NRRD headers the line) at fault.
#pragma once
#include <Eigen/Core>
#include <string>

#include "imaging/volume.h"

namespace surgsim::imaging {

/// Reads every *.png in `folder` as one slice; slices are ordered by the last number in their file name
/// (slice_007.png), which must run without gaps. Pixel values are labels: 1-, 2-, 4-, 8- or 16-bit grey (a binary
/// image's white is 1 at 1 bit, 255 at 8 bits), a palette image's indices, or grey stored as RGB(A) with equal
/// channels (alpha is ignored). Column -> i, row -> j, slice -> k. `spacing` (m) along i, j, k; the origin is 0.
/// Throws surgsim::core::Error naming the file for: no PNG in the folder, a name without a number, two slices with the
/// same number, a missing slice number, a slice whose size differs from the first's, an unreadable or colour PNG.
LabelVolume read_png_slices(const std::string& folder, const Eigen::Vector3d& spacing);

/// Reads an NRRD volume: `.nrrd` with the data attached after the header, or a detached header (`.nhdr`) whose
/// `data file:` names the raw data (relative to the header's folder). Supported: dimension 3; type uchar, ushort,
/// short, int or float (float values must be whole numbers: labels); encoding raw; endian little or big; sizes;
/// spacings, or space directions (orthogonal axes) with space origin; space units mm (the default), cm, m or um;
/// line skip and byte skip (-1: the data ends the file). Other informational fields (content, kinds, centers,
/// labels, units, thicknesses, axis mins/maxs, min/max, old min/max, measurement frame, space, sample units,
/// key:=value pairs) are accepted and ignored. Throws surgsim::core::Error "FILE:LINE: ..." for an unknown field or an
/// unsupported value (listing what is supported), and "FILE: ..." for truncated or missing data.
LabelVolume read_nrrd(const std::string& path);

/// Writes one 8-bit (labels 0..255) or 16-bit (up to 65535) grey PNG per k-slice: `folder`/`stem`_NNNN.png,
/// numbered from 0. Creates the folder. Throws for negative labels or labels above 65535.
void write_png_slices(const LabelVolume& volume, const std::string& folder, const std::string& stem = "slice");

/// How write_nrrd stores the voxels.
struct NrrdWriteOptions {
  std::string type = "uchar";  // uchar | ushort | short | int | float
  bool detached = false;       // true: `path` is the .nhdr header and the data goes to <path stem>.raw beside it
  bool big_endian = false;
  bool space_directions = true;  // write space directions + space origin (else spacings)
};

/// Writes the volume as NRRD (raw encoding, spacing in mm). Throws for labels the type cannot hold.
void write_nrrd(const LabelVolume& volume, const std::string& path, const NrrdWriteOptions& options = {});

}  // namespace surgsim::imaging
