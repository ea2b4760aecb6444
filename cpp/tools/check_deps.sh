#!/bin/sh
# What `make cpp` needs: cmake >= 3.18, a C++17 compiler, Eigen 3 headers, GoogleTest; ninja is
# used when present. As root on Debian/Ubuntu the missing packages are installed
# (apt-get update, then apt-get install -y, only if something is missing); otherwise the script
# names exactly what is missing and how to install it, and fails.
set -u

missing=""   # Debian packages
what=""      # human-readable list

need() {  # need <package> <description>
    missing="$missing $1"
    what="$what\n  - $2 (Debian/Ubuntu package: $1)"
}

has_header() {  # has_header <relative path> : in a system include directory
    for dir in /usr/include /usr/local/include; do
        [ -f "$dir/$1" ] && return 0
    done
    return 1
}

check() {
    missing=""
    what=""
    if command -v cmake >/dev/null 2>&1; then
        version=$(cmake --version | head -n 1 | sed 's/[^0-9.]*\([0-9][0-9.]*\).*/\1/')
        major=$(echo "$version" | cut -d. -f1)
        minor=$(echo "$version" | cut -d. -f2)
        if [ "$major" -lt 3 ] || { [ "$major" -eq 3 ] && [ "$minor" -lt 18 ]; }; then
            need cmake "cmake >= 3.18 (found $version)"
        fi
    else
        need cmake "cmake >= 3.18"
    fi
    if ! command -v "${CXX:-c++}" >/dev/null 2>&1 && ! command -v g++ >/dev/null 2>&1; then
        need g++ "a C++17 compiler (g++ >= 8 or clang++ >= 7)"
    fi
    has_header eigen3/Eigen/Core || need libeigen3-dev "Eigen 3 headers (eigen3/Eigen/Core)"
    has_header gtest/gtest.h || need libgtest-dev "GoogleTest (gtest/gtest.h)"
}

check
if [ -z "$missing" ]; then
    exit 0
fi
if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
    echo "make cpp: installing missing packages:$missing"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq && apt-get install -y -qq --no-install-recommends $missing || {
        echo "make cpp: apt-get install -y$missing failed" >&2
        exit 1
    }
    check
    [ -z "$missing" ] && exit 0
fi
printf "make cpp: missing:%b\n" "$what" >&2
echo "install with: sudo apt-get install -y$missing   (then run make cpp again)" >&2
exit 1
