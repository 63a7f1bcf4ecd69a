// SPDX-License-Identifier: GPL-2.0
/*
 * imucal-irq-i2c: test-only board code for tests/qemu/iio_guest.cpp. Not part of imucal.
 *
 * The kernel's inv-mpu6050 driver sets up its IIO buffer only when its I2C client has an
 * interrupt, and a client made through the adapter's new_device file never has one. This
 * module allocates an interrupt of its own (a dummy chip, as a GPIO controller's would be) and,
 * when "1" is written to /sys/module/imucal_irq_i2c/parameters/attach, creates the I2C client
 * <name> at <addr> on adapter <bus> with that interrupt, as board code or a device tree would
 * ("0" removes it). Each write of N to .../parameters/fire raises the interrupt N times, in the
 * writer's context with local interrupts off, as the chip's data-ready pulse would: the IIO
 * trigger's top half stamps the scan there.
 *
 * Built out of tree against the booted kernel's headers by tests/qemu/build-kmod.sh.
 */
#include <linux/i2c.h>
#include <linux/irq.h>
#include <linux/irqdesc.h>
#include <linux/module.h>
#include <linux/moduleparam.h>
#include <linux/mutex.h>

static int bus;
module_param(bus, int, 0444);
MODULE_PARM_DESC(bus, "I2C adapter number (default 0, i2c-stub's)");
static int addr = 0x68;
module_param(addr, int, 0444);
MODULE_PARM_DESC(addr, "client address (default 0x68)");
static char name[I2C_NAME_SIZE] = "mpu6050";
module_param_string(name, name, sizeof(name), 0444);
MODULE_PARM_DESC(name, "client type, an id of the driver to bind (default mpu6050)");

static int irq = -1;
module_param(irq, int, 0444);
MODULE_PARM_DESC(irq, "the interrupt given to the client (read-only: allocated at load)");

static struct i2c_client *client;
static DEFINE_MUTEX(lock);

static int attach_set(const char *val, const struct kernel_param *kp)
{
	struct i2c_board_info info = {};
	struct i2c_adapter *adap;
	struct i2c_client *made;
	bool on;
	int ret = 0;

	if (kstrtobool(val, &on))
		return -EINVAL;
	mutex_lock(&lock);
	if (on && !client) {
		adap = i2c_get_adapter(bus);
		if (!adap) {
			ret = -ENODEV;
			goto out;
		}
		strscpy(info.type, name, sizeof(info.type));
		info.addr = addr;
		info.irq = irq;
		made = i2c_new_client_device(adap, &info);
		i2c_put_adapter(adap);
		if (IS_ERR(made))
			ret = PTR_ERR(made);
		else
			client = made;
	} else if (!on && client) {
		i2c_unregister_device(client);
		client = NULL;
	}
out:
	mutex_unlock(&lock);
	return ret;
}

static int attach_get(char *buf, const struct kernel_param *kp)
{
	return sysfs_emit(buf, "%d\n", client ? 1 : 0);
}

static const struct kernel_param_ops attach_ops = {
	.set = attach_set,
	.get = attach_get,
};
module_param_cb(attach, &attach_ops, NULL, 0644);
MODULE_PARM_DESC(attach, "1: create the client with the interrupt, 0: remove it");

static int fire_set(const char *val, const struct kernel_param *kp)
{
	unsigned int n, i;
	int ret;

	if (kstrtouint(val, 0, &n) || n == 0 || n > 10000)
		return -EINVAL;
	for (i = 0; i < n; ++i) {
		ret = generic_handle_irq_safe(irq);
		if (ret)
			return ret;
	}
	return 0;
}

static const struct kernel_param_ops fire_ops = {
	.set = fire_set,
};
module_param_cb(fire, &fire_ops, NULL, 0200);
MODULE_PARM_DESC(fire, "N: raise the interrupt N times");

static int __init imucal_irq_i2c_init(void)
{
	irq = irq_alloc_desc_from(1, NUMA_NO_NODE);
	if (irq < 0)
		return irq;
	irq_set_chip_and_handler(irq, &dummy_irq_chip, handle_simple_irq);
	return 0;
}

static void __exit imucal_irq_i2c_exit(void)
{
	attach_set("0", NULL);
	irq_free_desc(irq);
}

module_init(imucal_irq_i2c_init);
module_exit(imucal_irq_i2c_exit);
MODULE_DESCRIPTION("imucal test: an I2C client with a software-raised interrupt");
MODULE_LICENSE("GPL");
