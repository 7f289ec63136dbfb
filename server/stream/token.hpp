// Token comparison shared by the protocol's Hello and the admin HTTP endpoint.
#pragma once

#include <string>

namespace hs::stream {

// Compares every byte whatever the first difference, so timing says nothing of the token.
bool same_token(const std::string& a, const std::string& b);

}  // namespace hs::stream
