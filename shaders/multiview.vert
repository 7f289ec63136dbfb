#version 450
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_multiview : require
#define HS_MULTIVIEW 1
#include "prop_vertex.glsl"
