#include "physreg/core/error.hpp"
