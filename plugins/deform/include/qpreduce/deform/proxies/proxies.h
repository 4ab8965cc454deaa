// qpreduce::deform — the proxies of the reduced deformable model (Ye & Yan,
// Section 3.1): everything in one include. Rotational clusters (Eq. 8) in
// clusters.h, drawn with kmeans.h on the embedding of spectral.h; linear
// proxies (Eq. 12) in linear_proxies.h. The method is in docs/proxies.md.
#pragma once

#include <qpreduce/deform/proxies/clusters.h>
#include <qpreduce/deform/proxies/kmeans.h>
#include <qpreduce/deform/proxies/linear_proxies.h>
#include <qpreduce/deform/proxies/spectral.h>
