# Convenience targets for developers; each calls build.sh (which installs missing packages).
.PHONY: all demo test unit system fuzz bench format
all:
	bash build.sh build
demo:
	bash build.sh demo
test:
	bash build.sh test
unit:
	bash build.sh unit
system:
	bash build.sh system
fuzz:
	bash build.sh fuzz
bench:
	bash build.sh bench
format:
	clang-format -i $$(git ls-files '*.cpp' '*.hpp')
