// vpl_shade kernels.
#pragma once

namespace voxgi {}
