// SPDX-License-Identifier: GPL-3.0-or-later
#include "registration/test_segmentation_registration.cpp"
#include "registration/test_image_baselines.cpp"
#include "test_support.cpp"
