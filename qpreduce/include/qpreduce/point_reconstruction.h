// qpreduce — reconstruction of points from a subspace basis kept in float
// (or in double, for answers to double precision) (the per-frame step 5 of
// the paper's Fig. 5: X = N·z + UD·y, read as n points).
//
// For a subspace X = B·w whose unknowns come in groups of three (the x, y, z
// coordinates of point v are X's entries 3v, 3v + 1, 3v + 2) and a global
// rotation R applied after it (Appendix, global rotation adaptation):
//
//   X_out.row(v) = (scale · R · B.middleRows<3>(3v) · w + offset)ᵀ   v = 0 … n − 1
//
//   B      3n × p   float (or double), row-major (each point's three rows
//                   contiguous)
//   w      p        the reduced coordinates [z; y], B's scalar
//   R      3 × 3    B's scalar
//   scale, offset    a map back from a normalised frame (Deformer::
//                    normalization), applied in double; 1 and 0 by default
//   X_out  n × 3    double, row-major (resized when its row count differs;
//                   the Map overload writes into the caller's n × 3 buffer,
//                   which must have n rows)
//
// Cost O(n·p), memory-bound for large n: B is read once, in order, by the
// OpenMP threads (static split over points); on CPUs with AVX2 + FMA each
// point is one pass over its three rows (simd_kernels.h), otherwise Eigen's
// product. Float sums of p products: each coordinate carries a round-off of
// order p·2⁻²⁴·Σ|B_aj·w_j| (2⁻⁵³ in double: Eigen's product per point, the
// same threads, twice the bytes read).
//
// Preconditions (std::invalid_argument otherwise, naming the argument):
// B.rows() divisible by 3; w.size() == B.cols(); w, R, scale and offset
// finite. B's entries
// are not scanned (O(n·p) per call); a non-finite B gives non-finite points.
#pragma once

#include "qpreduce/common.h"

namespace qpreduce {

using RowMatrixXf = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using RowMatrixXd = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using Points3d = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;

void reconstruct_points(const RowMatrixXf& B, const Eigen::VectorXf& w, const Eigen::Matrix3f& R, Points3d* X_out,
                        double scale = 1.0, const Eigen::Vector3d& offset = Eigen::Vector3d::Zero());
void reconstruct_points(const RowMatrixXf& B, const Eigen::VectorXf& w, const Eigen::Matrix3f& R,
                        Eigen::Map<Points3d> X_out, double scale = 1.0,
                        const Eigen::Vector3d& offset = Eigen::Vector3d::Zero());
void reconstruct_points(const RowMatrixXd& B, const Eigen::VectorXd& w, const Eigen::Matrix3d& R, Points3d* X_out,
                        double scale = 1.0, const Eigen::Vector3d& offset = Eigen::Vector3d::Zero());
void reconstruct_points(const RowMatrixXd& B, const Eigen::VectorXd& w, const Eigen::Matrix3d& R,
                        Eigen::Map<Points3d> X_out, double scale = 1.0,
                        const Eigen::Vector3d& offset = Eigen::Vector3d::Zero());

}  // namespace qpreduce
