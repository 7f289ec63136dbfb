#version 450
#extension GL_GOOGLE_include_directive : require
#include "prop_vertex.glsl"
